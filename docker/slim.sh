#!/bin/sh
# Cut from a virtual environment what the service and the client never use at run time.
# Usage: sh slim.sh VENV   (in the image's build stage, with binutils' strip installed)
set -eu
site=$(echo "$1"/lib/python3*/site-packages)
[ -d "$site/torch" ] || { echo "slim.sh: no torch under $site: is $1 the image's venv?" >&2; exit 1; }
command -v strip >/dev/null || { echo "slim.sh: strip not found (apt-get install binutils)" >&2; exit 1; }

# Packages that others require but the project never imports: sympy, mpmath and networkx
# (torch.compile and torch.export only), PyOpenGL (dm_control's renderers: no display here).
"$1/bin/pip" uninstall -q -y sympy mpmath networkx PyOpenGL
# torch's C++ headers, test suite and test programs (torch_shm_manager stays: shared memory).
rm -rf "$site/torch/include" "$site/torch/test" "$site"/torch/lib/lib*test*.so
find "$site/torch/bin" -type f ! -name torch_shm_manager -delete
# pyarrow's C++ tests and headers, Arrow Flight and S3 (pyarrow.fs does without _s3fs).
rm -rf "$site"/pyarrow/_pyarrow_cpp_tests* "$site/pyarrow/include" "$site"/pyarrow/libarrow_flight.so* \
    "$site"/pyarrow/libarrow_python_flight.so* "$site"/pyarrow/_flight.*.so "$site"/pyarrow/libarrow_s3.so* \
    "$site"/pyarrow/_s3fs.*.so
# Third-party test suites: never imported by their packages.
find "$site" -depth -type d -name tests -prune -exec rm -rf {} +
# dm_control's walker, maze and suite assets: the project uses its MJCF library only.
rm -rf "$site/dm_control/locomotion" "$site/dm_control/suite"
# MuJoCo's experimental Studio GUI (the simulation needs no viewer).
rm -rf "$site/mujoco/experimental"
# C and Cython sources shipped beside the compiled modules.
find "$site" -type f \( -name '*.c' -o -name '*.cpp' -o -name '*.pyx' -o -name '*.pxd' -o -name '*.pxi' \) -delete
# Debug symbols and symbol tables of every native file but those in the auditwheel-patched
# *.libs folders (stripping those can break them), and of rerun's CLI.
find "$site" -type f -name '*.so*' ! -path '*.libs/*' -exec strip --strip-unneeded {} +
strip --strip-unneeded "$site/rerun_cli/rerun"
# Byte-code: the build writes it back only for the modules the project imports (Dockerfile).
find "$site" -depth -type d -name __pycache__ -prune -exec rm -rf {} +
# Check that what was cut is not needed to load them.
"$1/bin/python" -c "import torch, llvmlite.binding, rerun, dm_control.mjcf, scipy, sklearn, mujoco, pyarrow.parquet, pyarrow.dataset, pyarrow.fs, foxglove, matplotlib"
"$1/bin/python" -m rerun --version
