"""The release: the sdist and wheel build and pass ``twine check``; the wheel, installed into a
new virtual environment (not editable, no source tree on the path), is one import name whose
command, public API, package data and an example work, even beside a user's own ``models``
and ``client`` packages; the public modules pass ``mypy --strict``.

The new environment finds the dependencies in this one's site-packages (a ``.pth`` line), so
that the check costs seconds rather than a second install of torch and MuJoCo.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PUBLIC_MODULES = ("neural_asm", "neural_asm.memory", "neural_asm.client.session")

pytestmark = pytest.mark.slow


def run(*cmd: str | Path, cwd: Path | None = None, env: dict[str, str] | None = None) -> str:
    result = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, f"{cmd}: {result.stdout[-2000:]}\n{result.stderr[-3000:]}"
    return result.stdout


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    run(sys.executable, "-m", "build", "--outdir", out, ROOT)
    return out


@pytest.fixture(scope="module")
def installed(dist, tmp_path_factory) -> Path:
    """A new virtual environment holding the wheel; its python."""
    env_dir = tmp_path_factory.mktemp("venv")
    venv.create(env_dir, with_pip=True)
    python = env_dir / "bin" / "python"
    run(python, "-m", "pip", "install", "--no-deps", "--no-index", "--quiet", *dist.glob("*.whl"))
    site = Path(run(python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])").strip())
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return python


@pytest.fixture
def shadowed(tmp_path) -> tuple[Path, dict[str, str]]:
    """A working folder holding a user's own ``models`` and ``client`` packages, and the environment to run in it."""
    for name in ("models", "client"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text(f"raise ImportError('the user own {name} package')\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return tmp_path, {**env, "NASM_HOME": str(tmp_path / "home")}


def test_twine_check_passes(dist):
    assert sorted(p.suffix for p in dist.iterdir()) == [".gz", ".whl"]
    run(sys.executable, "-m", "twine", "check", "--strict", *dist.iterdir())


def test_the_wheel_installs_one_top_level_name(installed):
    site = Path(run(installed, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])").strip())
    (dist_info,) = site.glob("neural_asm-*.dist-info")
    record = (dist_info / "RECORD").read_text()
    tops = {line.split(",")[0].split("/")[0] for line in record.splitlines() if line and not line.startswith("..")}
    assert tops == {"neural_asm", dist_info.name}
    assert (dist_info / "top_level.txt").read_text().split() == ["neural_asm"]


def test_the_installed_package_works_beside_a_users_own_packages(installed, shadowed):
    folder, env = shadowed
    out = run(installed, "-c", "import neural_asm, neural_asm.models.asm, neural_asm.client.session; "
              "print(neural_asm.__version__); print(neural_asm.__file__)", cwd=folder, env=env)
    version, where = out.split()
    assert version == "0.1.0" and "site-packages" in where and str(ROOT) not in where
    assert "Usage: nasm" in run(installed.parent / "nasm", "--help", cwd=folder, env=env)
    assert '"data_home"' in run(installed.parent / "nasm", "info", cwd=folder, env=env)
    layout = run(installed, "-c", "from importlib.resources import files; "
                 "print(sorted(p.name for p in (files('neural_asm.recordings') / 'layouts').iterdir()))", cwd=folder, env=env)
    assert ".json" in layout  # the Foxglove layout ships as package data


def test_an_example_runs_on_the_installed_package(installed, shadowed):
    folder, env = shadowed
    out = run(installed, ROOT / "examples" / "train_on_arrays.py", cwd=folder, env=env)
    assert "isolated joint joint2" in out


def test_the_public_modules_pass_mypy_strict(installed):
    args = [f"-m={m}" for m in PUBLIC_MODULES]
    run(sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent", "--no-incremental",
        "--python-executable", installed, *args, cwd=installed.parent)
