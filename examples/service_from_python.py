"""Host a skill memory in the service and stream an episode to it from Python.

    python examples/service_from_python.py

Trains a memory on simulated Panda demonstrations, saves the checkpoint into a models
folder, starts the service on a free loopback port in this process (``nasm serve`` runs the
same app), and streams a run with a locked joint over the websocket. The service's verdicts
are those ``SkillMemory.monitor`` gives for the same observations: the script checks it.
"""

import tempfile
from pathlib import Path

import neural_asm as nasm


def main() -> None:
    memory = nasm.SkillMemory.fit(nasm.simulate_sequences("demos", n_demos=10), progress=False)
    memory.calibrate(nasm.simulate_sequences("normal", n_normal=60))
    episode = nasm.run_episode("pick_right_place_left", seed=42,
                               fault=nasm.FaultSpec(joint=2, time_s=2.5, overshoot_deg=15.0))

    with tempfile.TemporaryDirectory() as folder:
        memory.save(Path(folder) / "panda.safetensors")  # hosted as model "panda"
        settings = nasm.ServiceSettings(models_dir=folder, record=False, build_default_model=False)
        with nasm.start_service(settings) as server:
            client = nasm.ServiceClient(server.url)
            print(f"service at {server.url} hosts {[m['name'] for m in client.models()]}")
            local = memory.monitor(fpr=0.05)
            with client.session(model="panda", fpr=0.05) as session:
                for x in episode.observations:
                    answer, verdict = session.step(x), local.step(x)
                    if answer.fault != verdict.fault or abs(answer.energy - verdict.energy) > 1e-6 * verdict.energy:
                        raise SystemExit(f"step {verdict.step}: the service and the local monitor disagree")
                    if answer.fault:
                        print(f"step {answer.step}: fault, isolated {answer.isolated_joint}, served in "
                              f"{answer.inference_ms:.2f} ms")
    print("the service and SkillMemory.monitor gave the same verdict at every step")


if __name__ == "__main__":
    main()
