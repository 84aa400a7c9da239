"""From a robot's ROS 2 bags to a calibrated skill memory the service can host.

    python examples/ros2_bag_to_model.py                          # makes bags of simulated runs first
    python examples/ros2_bag_to_model.py DEMOS NORMAL --mapping MAPPING.toml --out panda.safetensors

DEMOS and NORMAL are bag sources (a rosbag2 folder, a folder of them, or a ROS 1 ``.bag``)
read through a channel mapping: which topic field becomes which channel, in which units, on
which clock (``examples/panda_ros2.toml`` is one for a Panda). With no bags given, the
script writes two rosbag2 MCAP bags of simulated Panda runs (joint states at 40 Hz, the tool
position at 10 Hz, pad wrenches at 20 Hz, a marker per episode) and their mapping, so it
runs anywhere. ``nasm train/calibrate --mapping`` do the same from the shell.
"""

import argparse
import tempfile
from pathlib import Path

import neural_asm as nasm


def simulated_bags(folder: Path) -> tuple[Path, Path, Path]:
    """Two bags of simulated Panda runs (demonstrations, normal runs) and the mapping that reads them."""
    from neural_asm.experiments.robot_logs.write import bag_mapping, write_bag, write_mapping

    demos = write_bag(nasm.simulated_episodes("demos", n_demos=10), folder / "demos")
    normal = write_bag(nasm.simulated_episodes("normal", n_normal=40), folder / "normal", seed=1)
    return demos, normal, write_mapping(bag_mapping(), folder / "mapping.yaml")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("demos", nargs="?", type=Path, help="bags of demonstrations")
    parser.add_argument("normal", nargs="?", type=Path, help="bags of normal runs the model does not train on")
    parser.add_argument("--mapping", type=Path, help="the channel mapping (TOML or YAML)")
    parser.add_argument("--out", type=Path, default=Path("panda_from_bags.safetensors"), help="checkpoint to write")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if args.demos is None:
            args.demos, args.normal, args.mapping = simulated_bags(Path(tmp))
        elif args.normal is None or args.mapping is None:
            parser.error("give DEMOS, NORMAL and --mapping, or nothing")
        demos = nasm.read_logs(args.demos, args.mapping)
        print(f"{args.demos}: {len(demos)} episodes of {len(demos.channel_names)} channels at {demos.rate_hz:g} Hz, "
              f"skills {sorted(set(demos.labels.tolist()))}")
        memory = nasm.SkillMemory.fit(demos, progress=False)
        report = memory.calibrate(nasm.read_logs(args.normal, args.mapping))
    threshold = report["modes"]["offline"]["episode_thresholds"]["0.01"]
    print(f"calibrated on {report['threshold_episodes']} normal episodes: 1 % threshold {threshold:.1f}; "
          f"wrote {memory.save(args.out)} (nasm serve --models-dir {args.out.parent} hosts it)")


if __name__ == "__main__":
    main()
