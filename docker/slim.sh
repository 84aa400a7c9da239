#!/bin/sh
# Cut from a virtual environment what the service and the client never use at run time.
# Usage: sh slim.sh VENV   (in the image's build stage, with binutils' strip installed)
set -eu
site=$(echo "$1"/lib/python3*/site-packages)
[ -d "$site/torch" ] || { echo "slim.sh: no torch under $site: is $1 the image's venv?" >&2; exit 1; }
command -v strip >/dev/null || { echo "slim.sh: strip not found (apt-get install binutils)" >&2; exit 1; }

# Packages that others require but the project never imports: sympy, mpmath and networkx
# (torch.compile and torch.export; torch.optim's optimizers too, whose constructors import
# Dynamo: the project trains with an Adam of its own, models/kernels.py), PyOpenGL and glfw
# (dm_control's and MuJoCo's renderers: no display here), labmaze (the mazes of dm_control's
# locomotion, cut below). Dynamo and Inductor stay (15 MB): adding sympy brings them back.
"$1/bin/pip" uninstall -q -y sympy mpmath networkx PyOpenGL glfw labmaze
# matplotlib and what only it requires: the experiments' figures. Those commands say so and stop
# when it is missing (experiments/plotting.py); nothing else imports it.
"$1/bin/pip" uninstall -q -y matplotlib fonttools contourpy kiwisolver cycler python-dateutil
# torch's C++ headers, test suite and test programs (torch_shm_manager stays: shared memory).
rm -rf "$site/torch/include" "$site/torch/test" "$site"/torch/lib/lib*test*.so
find "$site/torch/bin" -type f ! -name torch_shm_manager -delete
# pyarrow's C++ tests, headers and sources, Arrow Flight and S3 (pyarrow.fs does without _s3fs).
# (pyarrow.lib links libarrow_substrait: it stays.)
rm -rf "$site"/pyarrow/_pyarrow_cpp_tests* "$site/pyarrow/include" "$site/pyarrow/src" "$site"/pyarrow/libarrow_flight.so* \
    "$site"/pyarrow/libarrow_python_flight.so* "$site"/pyarrow/_flight.*.so "$site"/pyarrow/libarrow_s3.so* \
    "$site"/pyarrow/_s3fs.*.so
# pyarrow's wheel holds each of its own libraries three times over (libX.so, libX.so.N and
# libX.so.N.M.P, which an installed library has as links): the two shorter names become links.
for lib in "$site"/pyarrow/lib*.so.*.*.*; do
    for name in "${lib%.*.*}" "${lib%.so.*}.so"; do
        if [ -f "$name" ] && [ ! -L "$name" ] && cmp -s "$name" "$lib"; then ln -sf "${lib##*/}" "$name"; fi
    done
done
# Third-party test suites and their data: never imported by their packages.
find "$site" -depth -type d \( -name tests -o -name testdata -o -name test_assets \) -prune -exec rm -rf {} +
find "$site/dm_control" "$site/mujoco" -type f -name '*_test.py' -delete
rm -rf "$site/dm_control/mujoco/testing/assets"
# dm_control's walker, maze and suite assets: the project uses its MJCF library only.
rm -rf "$site/dm_control/locomotion" "$site/dm_control/suite"
# MuJoCo's experimental Studio GUI and its Filament renderer (the simulation needs no viewer).
rm -rf "$site/mujoco/experimental" "$site"/mujoco/_render_filament.*.so "$site/mujoco/mjrf.py"
# C and Cython sources and C headers shipped beside the compiled modules (for building against
# them), and type stubs (for type checkers).
find "$site" -type f \( -name '*.c' -o -name '*.cpp' -o -name '*.h' -o -name '*.hpp' -o -name '*.pyx' \
    -o -name '*.pxd' -o -name '*.pxi' -o -name '*.pyi' \) -delete
# Debug symbols and symbol tables of every native file but those in the auditwheel-patched
# *.libs folders (stripping those can break them), and of rerun's CLI.
find "$site" -type f -name '*.so*' ! -path '*.libs/*' -exec strip --strip-unneeded {} +
strip --strip-unneeded "$site/rerun_cli/rerun"
# rerun's CLI (239 MiB) runs only to recover a .rrd cut short by a crash. It is kept compressed
# (zstd, 72 MB) and a launcher under its name unpacks it into memory and runs it: 0.4 s more
# per run, what UPX would do (Debian 12 has no upx package). zstandard is in the venv for mcap.
cli="$site/rerun_cli/rerun"
"$1/bin/python" -c "if True:
    import sys, zstandard
    with open(sys.argv[1], 'rb') as src, open(sys.argv[1] + '.zst', 'wb') as dst:
        zstandard.ZstdCompressor(level=9, threads=-1).copy_stream(src, dst)" "$cli"
cat > "$cli" <<LAUNCHER
#!$1/bin/python
# rerun's CLI, packed by docker/slim.sh into rerun.zst beside this file: unpacked into memory, run.
import os, sys, zstandard
fd = os.memfd_create("rerun", 0)
with open(os.path.realpath(__file__) + ".zst", "rb") as src, open(fd, "wb", closefd=False) as dst:
    zstandard.ZstdDecompressor().copy_stream(src, dst)
os.execv(f"/proc/self/fd/{fd}", ["rerun", *sys.argv[1:]])
LAUNCHER
# Byte-code: the build writes it back only for the modules the project imports (Dockerfile).
find "$site" -depth -type d -name __pycache__ -prune -exec rm -rf {} +
# Check that what was cut is not needed to load them.
"$1/bin/python" -c "import torch, llvmlite.binding, rerun, dm_control.mjcf, scipy, sklearn, mujoco, pyarrow.parquet, pyarrow.dataset, pyarrow.fs, foxglove"
# (not torch.optim's optimizers: their constructors import torch._dynamo, so sympy)
"$1/bin/python" -c "import torch; m = torch.nn.Linear(4, 2); m(torch.zeros(3, 4)).sum().backward()"
"$1/bin/python" -m rerun --version
