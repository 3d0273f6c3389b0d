#!/usr/bin/env bash
# One measuring call on a lent 16-core GPU machine (agents/device_check.py says
# what it measures). Run from the repository root, with the wheels of the packages that
# machine lacks in .whl/ (carried: pydantic, gymnasium, pymunk, cma and their needs):
#   bash agents/device_check.sh [driver options, e.g. --quick]
# It installs the wheels and this repository into $SITE (default a new temporary folder) without the
# network, prints the versions and the GPUs, then runs the driver; everything goes to
# $OUT (the device tool's folder; default out/device-check), device_check.log included.
# PYTHON (default python3), SITE and LIMIT (the driver's hard stop, s; default 450) can be set.
# A SITE named by the caller that already holds these same sources (a digest of spreadgym/, envs/, configs/
# and agents/, the driver aside) is used as it is, its driver refreshed: a second call on the same warm
# machine keeps its compiled kernels (reinstalling would renew the sources' times and so drop numba's
# caches); other sources there are reinstalled.
# MPS=1 runs the driver under NVIDIA's Multi-Process Service (started here, stopped at the end or when
# the script exits), so that the GPU launches of the vector env's worker processes may overlap;
# env.json records whether it ran.
set -u
export PYTHONUNBUFFERED=1
PY=${PYTHON:-python3}
SITE=${SITE:-$(mktemp -d)}
OUT=${OUT:-$PWD/out/device-check}
mkdir -p "$OUT"
start=$(date +%s)
sources_digest() {  # what numba's caches in $SITE were compiled from (the driver is no kernel source)
  find spreadgym envs configs agents -type f \( -name '*.py' -o -name '*.yaml' \) ! -name device_check.py \
    ! -path '*/__pycache__/*' | LC_ALL=C sort | xargs sha256sum | sha256sum | cut -c1-16
}
digest=$(sources_digest)
{
  mkdir -p "$SITE/lib"
  if [ -d "$SITE/spreadgym" ] && [ "$(cat "$SITE/.sources" 2>/dev/null)" = "$digest" ]; then
    cp agents/device_check.py "$SITE/spreadgym/agents/device_check.py"
    echo "$SITE already holds these sources ($digest): used as it is, the driver refreshed"
  else
    if [ -d "$SITE/spreadgym" ]; then
      echo "$SITE holds other sources than these ($digest): reinstalled"
      rm -rf "$SITE/spreadgym"
    fi
    if [ -d .whl ]; then
      $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" .whl/*.whl \
        || echo "!! wheel install failed"
    fi
    # the repository as pyproject maps it (envs/ -> spreadgym.envs, agents/ -> spreadgym.agents, configs/ -> spreadgym.configs)
    if ! $PY -m pip install -q --no-index --no-deps --no-build-isolation --no-compile --no-cache-dir --upgrade \
        --target "$SITE" . ; then
      echo "!! pip could not install the repository: copying its packages into $SITE instead"
      rm -rf "$SITE/spreadgym" && cp -r spreadgym "$SITE/" && cp -r envs "$SITE/spreadgym/envs" \
        && cp -r agents "$SITE/spreadgym/agents" && cp -r configs "$SITE/spreadgym/configs"
    fi
    echo "$digest" > "$SITE/.sources"
  fi
  export PYTHONPATH=$SITE${PYTHONPATH:+:$PYTHONPATH}
  # pip --target drops a wheel's data files, where pip's tbb keeps its libraries: unpack them beside
  # and let the loader find them, so numba takes oneTBB as the default install does (env.json says which layer ran)
  for wheel in .whl/tbb-*.whl .whl/tcmlib-*.whl; do
    [ -f "$wheel" ] && $PY -c 'import sys, zipfile, os
with zipfile.ZipFile(sys.argv[1]) as z:
    for name in z.namelist():
        if "/data/lib/" in name and not name.endswith("/"):
            target = os.path.join(sys.argv[2], os.path.basename(name))
            with open(target, "wb") as f:
                f.write(z.read(name))' "$wheel" "$SITE/lib"
  done
  export LD_LIBRARY_PATH=$SITE/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  if [ -z "${CUDA_HOME:-}" ] && [ -d /usr/local/cuda ]; then export CUDA_HOME=/usr/local/cuda; fi
  echo "installed in $(( $(date +%s) - start )) s; nproc $(nproc); CUDA_HOME=${CUDA_HOME:-unset}"
  $PY -c 'import sys, numpy, numba; print("python", sys.version.split()[0], "numpy", numpy.__version__, "numba", numba.__version__)'
  $PY -c 'import importlib.metadata as m; print("numba-cuda", m.version("numba-cuda"))' 2>/dev/null \
    || echo "numba-cuda: not installed"
  nvidia-smi -L 2>/dev/null || echo "nvidia-smi: none"
  # whether launches of different processes (the vector env's GPU workers) can overlap: only under NVIDIA's MPS
  nvidia-smi --query-gpu=compute_mode --format=csv,noheader 2>/dev/null | sed 's/^/compute mode: /'
  if pgrep -x nvidia-cuda-mps-control > /dev/null 2>&1; then echo "MPS: running"; else echo "MPS: not running"; fi
  echo "libnvvm: $(ls /usr/local/cuda*/nvvm/lib64/libnvvm.so* 2>/dev/null | head -2 | tr '\n' ' ')"
  echo "MPS control: $(command -v nvidia-cuda-mps-control || echo none)"
  mps=0
  if [ "${MPS:-0}" = 1 ]; then
    export CUDA_MPS_PIPE_DIRECTORY=$SITE/mps-pipe CUDA_MPS_LOG_DIRECTORY=$SITE/mps-log
    rm -rf "$CUDA_MPS_PIPE_DIRECTORY"  # a daemon killed before left its pipes
    mkdir -p "$CUDA_MPS_PIPE_DIRECTORY" "$CUDA_MPS_LOG_DIRECTORY"
    if nvidia-cuda-mps-control -d; then
      mps=1
      trap 'echo quit | nvidia-cuda-mps-control > /dev/null 2>&1' EXIT
      echo "MPS: started"
    else
      echo "!! MPS did not start: the run goes on without it"
    fi
  fi
  export DEVICE_CHECK_MPS=$mps
  timeout -k 15 "${LIMIT:-450}" $PY -P -m spreadgym.agents.device_check --out "$OUT" "$@"
  rc=$?
  if [ "$mps" = 1 ]; then
    echo quit | nvidia-cuda-mps-control && echo "MPS: stopped"
    trap - EXIT
    tail -5 "$CUDA_MPS_LOG_DIRECTORY"/control.log 2>/dev/null
  fi
  echo "device_check.sh: $(( $(date +%s) - start )) s in all (driver exit $rc)"
} 2>&1 | tee "$OUT/device_check.log"
