"""Monitor a simulated Franka Panda step by step, as a robot's control loop would.

    python examples/monitor_stream.py

Trains a skill memory on 20 simulated pick-and-place demonstrations, calibrates it on 100
normal runs it has not seen (half set the precisions, half the threshold: a 5 % false-alarm
rate per episode; rarer alarms need more normal runs), then watches two new runs observation
by observation: a normal one, and one whose joint 4 locks 5 degrees past its goal at t = 3 s. ``Monitor.step`` returns
the verdict the service gives for the same observation.
"""

import neural_asm as nasm


def watch(memory: nasm.SkillMemory, episode: nasm.Episode, title: str) -> None:
    monitor = memory.monitor(fpr=0.05)
    print(f"{title} ({episode.skill}, seed {episode.seed}):")
    for x in episode.observations:  # one observation every 0.5 s, as they arrive
        verdict = monitor.step(x)
        flag = f"FAULT, isolated {verdict.isolated_joint}" if verdict.fault else "ok"
        print(f"  t = {verdict.step / episode.rate_hz:4.1f} s  energy {verdict.energy:8.1f} / {verdict.threshold:6.1f}  {flag}")


def main() -> None:
    demos = nasm.simulate_sequences("demos", n_demos=10)
    normal = nasm.simulate_sequences("normal", n_normal=100)
    memory = nasm.SkillMemory.fit(demos, progress=False)
    memory.calibrate(normal)

    watch(memory, nasm.run_episode("pick_left_place_right", seed=777), "normal run")
    lock = nasm.FaultSpec(joint=4, time_s=3.0, overshoot_deg=5.0)
    watch(memory, nasm.run_episode("pick_left_place_right", seed=777, fault=lock), "joint 4 locked at 3 s")


if __name__ == "__main__":
    main()
