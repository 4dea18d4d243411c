"""``ccjax train-net``: train the neural-net estimator and cache its weights (Barnard 1999 §4.5.5)."""

from __future__ import annotations

import sys

from ccjax.cli.common import build_world, world_arguments


def add_train_net(sub) -> None:
    p = sub.add_parser(
        "train-net",
        help="train the neural-net estimator for a world and cache its weights",
        description="Train NEURAL-NET (or SP-NEURAL-NET with --specular) on synthetic scenes of the world's training "
        "illuminants (Barnard 1999 §4.5.5) and save the weights in the cache ($CCJAX_CACHE, else the user "
        "cache directory).",
    )
    world_arguments(p)
    p.add_argument(
        "--specular",
        action="store_true",
        help="train SP-NEURAL-NET (specular training scenes) instead of NEURAL-NET",
    )
    p.add_argument("--steps", type=int, default=None, help="optimiser steps (default: 3000)")
    p.add_argument(
        "--batch-size",
        type=int,
        default=None,
        help="training scenes per step (default: 256)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run_train_net)


def run_train_net(args) -> int:
    import dataclasses

    from ccjax.estimators import neural

    label = "SP-NEURAL-NET" if args.specular else "NEURAL-NET"
    world = build_world(args)
    changes = {"seed": args.seed}
    if args.steps is not None:
        changes["steps"] = args.steps
    if args.batch_size is not None:
        changes["batch_size"] = args.batch_size
    schedule = dataclasses.replace(neural.Schedule(), **changes)
    print(
        f"training {label} for world {world.name}: {schedule.steps} steps x {schedule.batch_size} scenes",
        file=sys.stderr,
    )
    path, log = neural.train_and_save(world, label, schedule, progress=not args.no_progress)
    print(f"{label}: final training RMS (r,g) error {log.losses[-1] ** 0.5:.4f}; trained in {log.seconds:.1f} s")
    print(f"saved {path}")
    return 0


COMMANDS = [add_train_net]
