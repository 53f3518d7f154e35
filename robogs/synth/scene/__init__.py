"""Synthetic push scenes: an arm pushing a box on a table, with independent ground truth.

``synthesize(out, seed=0, size="small")`` writes a complete robogs dataset
(robot URDF + MDH, meshes, splats bound to faces, physics, camera, joint
states, actions, end-effector and object poses, RGB video, panoptic labels,
2D/3D boxes). Its kinematics, rasteriser and dynamics are the generator's own
and share no code with ``robogs.format``'s kinematics, renderer or checks, so
the result can serve as ground truth for them. The ground truth itself goes to
``ground_truth_path(out)`` (``<out>.ground_truth.json``), beside the dataset.

Choices of the scene (all in SI units, world z up, origin at the robot base):

* table: a static box, top surface ``z = 0`` (the robot base stands on it),
  1.2 x 1.0 x 0.04 m centred at (0.30, 0, -0.02); asset kind ``table``, physics
  equation ``static``, segment kind ``background`` with target ``table``.
* box: 0.10 x 0.08 x 0.06 m, 0.5 kg, frame at its centre (z = 0.03 at rest).
* tool: link ``pusher_tip``, 0.12 m below the flange ``tool0`` along its z axis,
  a sphere of radius 0.02 m centred on the link origin (plus a 9 mm rod up to
  the flange); ``ee_poses`` and the MDH ``T_tool`` refer to it.
* labels: 0 unlabelled; robot links with visual geometry 1..L in URDF link
  order; box 100; table 200.
* rest state of the splats: the episode start (``t_ns`` = start_ns), the true
  joint angles and object poses at that instant.
* splat colour: in the images' colour space, as in 3DGS (the SH colour is the
  pixel colour). Each Gaussian's DC term holds the sRGB-encoded, Lambert-shaded
  colour of its face at the rest state, with the light fixed in the world. This
  is exact for the table. For the links and the box it is approximate, because
  their faces change shade as they rotate away from the rest pose.
* stamps: sensor-like, a nominal grid plus uniform jitter (joint states 500 Hz
  +-0.05 ms, actions 125 Hz +-0.1 ms, object poses 120 Hz +-0.3 ms, camera
  30 fps +-2 ms); every frame is rendered at its own stamp.
"""

from .generate import CAMERA_NAME, EPISODE_ID, ground_truth_path, synthesize

__all__ = ["synthesize", "ground_truth_path", "EPISODE_ID", "CAMERA_NAME"]
