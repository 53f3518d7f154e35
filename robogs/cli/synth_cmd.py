"""``robogs synth OUT [--seed N] [--size small|medium|large] [--urdf PATH] [--splat-spacing M]``.

With ``--capture static [--no-poses]`` it writes the multi-view scan of the scene at rest
(60/120/180 views of 320x240/640x480/960x720 px by ``--size``; ``robogs.synth.multiview``) for
``robogs reconstruct``; the true camera poses and scene mesh go beside it.

With ``--effect NAME`` (``none`` for null data) it writes a hidden-effect scenario for the
physics loop instead: pushes at 3 speeds x 3 directions, off-centre pushes, release-and-slide
and grasp-lift-place, measured at ``--noise nominal|hard``; the hidden effect and its values go
beside the dataset, to ``OUT.truth.json``, never inside it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from robogs.format.errors import InputError

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``robogs synth``."""
    parser.add_argument("out", type=Path, help="dataset folder to create")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument(
        "--size",
        choices=("small", "medium", "large"),
        default="small",
        help="small: 4 s 160x120; medium: 20 s 320x240; large: 60 s 640x480",
    )
    parser.add_argument(
        "--urdf", type=Path, default=None, help="use this robot instead of the generated UR5"
    )
    parser.add_argument(
        "--splat-spacing",
        type=float,
        default=None,
        metavar="M",
        help="mean surfel spacing of the splats, m (default by --size: 0.010/0.006/0.004); "
        "finer resolves thin links' edges (aim for <= 1 px at the render resolution), "
        "at ~1/M^2 surfels (each target capped at 60,000)",
    )
    parser.add_argument(
        "--package",
        action="append",
        default=[],
        metavar="NAME=DIR",
        help="root folder of a package:// name used by --urdf (repeatable)",
    )
    parser.add_argument(
        "--effect",
        default=None,
        metavar="NAME",
        help="write a hidden-effect physics scenario with this effect ('none' for null data)",
    )
    parser.add_argument(
        "--noise", choices=("nominal", "hard"), default="nominal", help="scenario noise level"
    )
    parser.add_argument(
        "--capture",
        choices=("static",),
        default=None,
        help="static: the multi-view scan of the scene at rest (robot, box, table) to "
        "reconstruct from, instead of the manipulation episode",
    )
    parser.add_argument(
        "--no-poses",
        action="store_true",
        help="with --capture: images, intrinsics and labels only (camera extrinsics 'unknown'); "
        "the true poses go beside OUT",
    )
    parser.add_argument(
        "--episodes",
        type=int,
        default=None,
        metavar="N",
        help="write N short episodes of a planar 3R arm (joint_states and ee_poses, no cameras) "
        "for load and scale tests (robogs.synth.bulk; --episode-seconds each)",
    )
    parser.add_argument(
        "--episode-seconds",
        type=float,
        default=1.0,
        metavar="S",
        help="with --episodes: length of each episode, s (default 1, at 500 Hz)",
    )
    parser.add_argument(
        "--chunk-size",
        type=int,
        default=None,
        metavar="K",
        help="with --episodes: K episodes per episodes/chunk-NNN/ folder (spec 1.1 sharded "
        "layout; 0 = flat); default 1000 when N > 100, flat otherwise",
    )
    parser.add_argument("--force", action="store_true", help="replace OUT if it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Generate the dataset; print where it and its ground truth are. Returns 0."""
    from robogs.synth.scene.generate import ground_truth_path, synthesize

    if getattr(args, "splat_spacing", None) is not None and any(
        x is not None for x in (args.effect, args.capture, getattr(args, "episodes", None))
    ):
        raise InputError(
            "--splat-spacing applies to the manipulation episode only",
            hint="drop it, or drop --effect / --capture / --episodes",
        )
    if getattr(args, "episodes", None) is not None:
        from robogs.synth.bulk import bulk_cli

        return bulk_cli(args)
    if args.effect is not None:
        return _scenario(args)
    if args.capture is not None or args.no_poses:
        return _capture(args)
    roots = {}
    for item in args.package:
        name, sep, folder = item.partition("=")
        if not sep or not name or not folder:
            raise InputError(f"--package expects NAME=DIR, got {item!r}")
        roots[name] = Path(folder)
    if args.urdf is not None and Path(args.urdf).is_file():  # package:// as ROS/yourdfpy find it
        from robogs.format.packages import find_packages, package_uris

        uris = package_uris(Path(args.urdf).read_text(encoding="utf-8", errors="replace"))
        found = find_packages(uris, Path(args.urdf).resolve().parent, explicit=roots)
        for name, pkg in sorted(found.items()):
            roots[name] = pkg.path
            if pkg.how != "--package":
                print(f"package://{name}: {pkg.path} ({pkg.how})")
    out = synthesize(
        args.out,
        seed=args.seed,
        size=args.size,
        urdf=args.urdf,
        overwrite=args.force,
        progress=not args.quiet,
        package_roots=roots or None,
        splat_spacing_m=getattr(args, "splat_spacing", None),
    )
    print(f"wrote {out} (ground truth: {ground_truth_path(out)})")
    return 0


#: --size -> (views, width, height) of --capture static
CAPTURE_SIZES = {"small": (60, 320, 240), "medium": (120, 640, 480), "large": (180, 960, 720)}


def _capture(args: argparse.Namespace) -> int:
    from robogs.synth.multiview import synthesize_multiview, write_truth

    if args.capture is None:
        raise InputError("--no-poses needs --capture static")
    if args.urdf is not None or args.effect is not None:
        raise InputError(
            "--capture static scans the generated UR5 scene; it takes no --urdf or --effect"
        )
    n, w, h = CAPTURE_SIZES[args.size]
    truth = synthesize_multiview(
        args.out,
        robot="ur5",
        n_views=n,
        width=w,
        height=h,
        seed=args.seed,
        overwrite=args.force,
        poses=not args.no_poses,
    )
    gt = write_truth(truth, args.out)
    what = "images only, camera poses unknown" if args.no_poses else "with camera poses"
    print(f"wrote {args.out} ({n} views of {w}x{h}, {what}; ground truth: {gt})")
    return 0


def _scenario(args: argparse.Namespace) -> int:
    from robogs.synth.scenarios import TRUE_PARAMS, make_scenario, truth_path, write_scenario

    if args.effect not in TRUE_PARAMS:
        raise InputError(
            f"unknown effect {args.effect!r}",
            hint=f"choose one of {', '.join(sorted(TRUE_PARAMS))}",
        )
    try:
        rec = make_scenario(args.effect, seed=args.seed, noise=args.noise)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    write_scenario(rec, args.out, overwrite=args.force)
    print(
        f"wrote {args.out} (noise: {args.noise}; the hidden effect is recorded beside it, "
        f"in {truth_path(args.out)})"
    )
    return 0
