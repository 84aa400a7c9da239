#!/bin/sh
# Cut from a virtual environment what the service and the client never use at run time.
# Usage: sh slim.sh VENV   (in the image's build stage, with binutils' strip installed)
set -eu
site=$(echo "$1"/lib/python3*/site-packages)
[ -d "$site/torch" ] || { echo "slim.sh: no torch under $site: is $1 the image's venv?" >&2; exit 1; }
command -v strip >/dev/null || { echo "slim.sh: strip not found (apt-get install binutils)" >&2; exit 1; }

# torch's C++ headers, test suite and test programs (torch_shm_manager stays: shared memory).
rm -rf "$site/torch/include" "$site/torch/test" "$site"/torch/lib/lib*test*.so
find "$site/torch/bin" -type f ! -name torch_shm_manager -delete
# pyarrow's C++ tests (its other libraries stay: pyarrow.lib links Flight, S3, Substrait).
rm -f "$site"/pyarrow/_pyarrow_cpp_tests*
# Third-party test suites: never imported by their packages.
find "$site" -depth -type d -name tests -prune -exec rm -rf {} +
# dm_control's walker and maze assets: the project uses its MJCF library only.
rm -rf "$site/dm_control/locomotion"
# Debug symbols of the four largest native files. Only these: stripping the auditwheel-
# patched libraries (*.libs folders) can break them.
for f in torch/lib/libtorch_cpu.so rerun_cli/rerun rerun_bindings/rerun_bindings.abi3.so \
         llvmlite/binding/libllvmlite.so; do
    strip --strip-unneeded "$site/$f"
done
# Byte-code: the build writes it back only for the modules the project imports (Dockerfile).
find "$site" -depth -type d -name __pycache__ -prune -exec rm -rf {} +
# Check that what was cut is not needed to load them.
"$1/bin/python" -c "import torch, llvmlite.binding, rerun, dm_control.mjcf, scipy, sklearn, mujoco, pyarrow.parquet, pyarrow.dataset, pyarrow.fs"
"$1/bin/python" -m rerun --version
