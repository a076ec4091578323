"""`safl-bench data prepare`: build and cache top-view maps (clean + noise conditions)."""

from __future__ import annotations

import argparse

from safl_bench.cli.options import add_parallel_arguments, parallel_from, seed
from safl_bench.errors import ConfigError
from safl_bench.views.mapbuild import DEFAULT_STEP, KINDS, select_frames
from safl_bench.views.mapconfig import BACKENDS, ENCODINGS, MapConfig, config_for_encoding
from safl_bench.views.noise import CLEAN, PAPER_CONDITIONS, Condition

HELP = "build and cache the top-view maps of sequences (synthetic default or --kitti-root)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `data prepare`."""
    parser.add_argument("--kitti-root", metavar="DIR", default=None,
                        help="KITTI odometry root (default: the synthetic default, generated if missing)")
    parser.add_argument("--sequences", nargs="+", metavar="XX", default=None,
                        help="sequences to prepare (default: the synthetic test sequences 00 09)")
    parser.add_argument("--step", type=int, default=DEFAULT_STEP,
                        help=f"use every STEP-th frame (default {DEFAULT_STEP}, as the paper's code)")
    parser.add_argument("--backend", choices=BACKENDS, default=MapConfig.backend,
                        help="local-map backend (default: %(default)s)")
    parser.add_argument("--encoding", choices=ENCODINGS, default=MapConfig.encoding,
                        help="top-view encoding (default: %(default)s); bev-density brings its own "
                             "size, voxel, window and crop (BEVPlace's, mapconfig.bev_density_config)")
    parser.add_argument("--conditions", nargs="+", metavar="COND", default=["paper"],
                        help="'paper' (clean + the 12 conditions), 'clean', or names like T1R1 "
                             "(default: paper)")
    parser.add_argument("--kinds", nargs="+", choices=KINDS, default=["topview"],
                        help="views to cache (default: topview)")
    parser.add_argument("--seed", type=seed, default=0, help="noise seed and synthetic seed (default 0)")
    add_parallel_arguments(parser, "build the maps (chunks of each sequence's frames)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def parse_conditions(names: list[str]) -> list[Condition]:
    """'paper' -> clean + 12 paper conditions; 'clean'; 'T{a}R{b}'. Order kept, no repeats."""
    out: list[Condition] = []
    for name in names:
        if name == "paper":
            out += [CLEAN, *PAPER_CONDITIONS]
        elif name == "clean":
            out.append(CLEAN)
        else:
            out.append(Condition.parse(name))
    return list(dict.fromkeys(out))


def main(args: argparse.Namespace) -> int:
    from safl_bench.sources import resolve_source
    from safl_bench.views.mapcache import prepare_sequences

    if args.step < 1:
        raise ConfigError(f"--step must be >= 1, got {args.step}")
    conditions = parse_conditions(args.conditions)
    parallel = parallel_from(args)
    config = config_for_encoding(args.encoding, backend=args.backend)
    source = resolve_source(args.kitti_root, sequences=args.sequences, seed=args.seed,
                            progress=not args.quiet)
    sequences = args.sequences
    if sequences is None:
        from safl_bench import synth

        sequences = list(synth.TEST_SEQUENCES)
    frames = {name: select_frames(len(source.sequence(name)), args.step) for name in sequences}
    # one queue of map chunks for all sequences: the workers never wait between sequences
    done = prepare_sequences(source, frames, config, conditions=conditions, seed=args.seed,
                             kinds=args.kinds, progress=not args.quiet, parallel=parallel)
    for name, paths in done.items():
        folder = next(iter(paths.values())).parent
        print(f"{source.label} sequence {name}: {len(frames[name])} frames x {len(conditions)} "
              f"conditions x {len(args.kinds)} kinds cached in {folder}")
    return 0
