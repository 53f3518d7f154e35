"""robogs: an open format and toolkit for Real2Sim digital twins of robot-arm manipulation scenes.

Subpackages (each imported only when used):

- :mod:`robogs.format` — the dataset format: IO, conventions, kinematics, binding, renderer,
  validator, QA output;
- :mod:`robogs.convert` — converters in (bags, MCAP, video, captures, tabular logs) and out
  (URDF, USD, MCAP, PLY, Rerun);
- :mod:`robogs.reconstruct` — the reference reconstructor;
- :mod:`robogs.physics` — the physics loop (compare, diagnose, fit, report);
- :mod:`robogs.synth` — synthetic scenes and scenarios, independent of the code they test;
- :mod:`robogs.cli` — the ``robogs`` and ``robogs-validate`` commands.
"""

__version__ = "0.2.0"
