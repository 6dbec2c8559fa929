#!/usr/bin/env bash
# One GPU lease's measurements for the Newton loop's latency and the batched fits (issue 46).
#
# Runs on the device machine (docs/performance.md, "Newton iterations of small problems on a
# GPU"):
#
#   bash gpu_session.sh LABEL SITE MODE
#
# LABEL names the code measured (e.g. before, after), SITE is the folder the project was
# installed into (pip --target; its dependencies in /tmp/site), MODE is "profile" (cProfile
# of the main job and its forward run, the per-phase profiles), "time" (the timed runs for the
# tables, each with the factorization reused by GMRES and without), "quick" (the main job's
# forward-run latency and fit alone), "batch" (the batched fits at K = 1, 8, 32, 128 with a
# cProfile of K = 32), "cluster" (32 fits batched on the GPU against a warmed Dask
# LocalCluster of 16 CPU workers), "equality" (the main job and its forward run on the GPU and
# on this host's CPU, compared) or "suite" (the fast test suite, `pytest -n 14`, run
# from a copy of the checkout). Every output goes to $OUT/LABEL/ (JSON, pstats summaries as
# text, logs); nothing is asserted here.
set -uo pipefail
label=$1 site=$2 mode=$3
here=$(cd "$(dirname "$0")" && pwd)
export PYTHONPATH="$site:/tmp/site" PYTHONUNBUFFERED=1 OMP_NUM_THREADS=4
out="$OUT/$label"
mkdir -p "$out"
work=/tmp/w-$label
rm -rf "$work" && mkdir -p "$work" && cp -r "$here/../../scenes" "$here/../../scripts" "$work/"
cd "$work" || exit 1
cli=(python3 -m warptissue.cli)
stats() {  # pstats file -> text summary (tottime and cumtime, top 45 each)
  python3 - "$1" > "$1.txt" <<'PY'
import pstats, sys
s = pstats.Stats(sys.argv[1])
s.sort_stats("tottime").print_stats("warptissue|nvmath|cupy|warp", 70)
s.sort_stats("cumulative").print_stats("warptissue|nvmath|cupy|warp", 70)
PY
  rm -f "$1"
}
timed() {  # name command...: wall time into $out/walls.txt
  local name=$1; shift
  local t0=$(date +%s.%N)
  "$@" > "$out/$name.log" 2>&1
  local rc=$?
  local t1=$(date +%s.%N)
  echo "$name rc=$rc wall_s=$(python3 -c "print(round($t1 - $t0, 2))")" | tee -a "$out/walls.txt"
}
if [ "$mode" = profile ] || [ "$mode" = time ]; then
  # warm the kernel cache (the first run compiles) and CuPy's kernels
  timed warm_simulate "${cli[@]}" simulate scenes/liver_fit.toml --device cuda --quiet --out runs/warm
  timed fit "${cli[@]}" fit indentation scenes/liver_fit.toml --device cuda --quiet --out runs/fit
  cp runs/fit/fit.json "$out/fit.json"
  timed flat_punch python3 scripts/benchmarks/bench_flat_punch.py --device cuda --mesher delaunay \
    --sizes 3k,10k --elimination auto --reuse on,off --profile --label "$label" \
    --out "$out/flat_punch.json"
  timed latency python3 scripts/benchmarks/bench_newton_latency.py scenes/liver_fit.toml \
    --device cuda --repeats 3 --label "$label" --out "$out/latency.json"
  sed 's/^\[solver\]$/[solver]\nreuse_factorization = false/' scenes/liver_fit.toml > scenes/liver_fit_fresh.toml
  timed latency_no_reuse python3 scripts/benchmarks/bench_newton_latency.py \
    scenes/liver_fit_fresh.toml --device cuda --repeats 3 --label "$label no reuse" \
    --out "$out/latency_no_reuse.json"
  cp runs/warm/result.json "$out/simulate_cuda_result.json"
fi
if [ "$mode" = quick ]; then  # the forward run's latency (its warm-up compiles) and the fit
  timed latency python3 scripts/benchmarks/bench_newton_latency.py scenes/liver_fit.toml \
    --device cuda --repeats 3 --label "$label" --out "$out/latency.json"
  timed fit "${cli[@]}" fit indentation scenes/liver_fit.toml --device cuda --quiet --out runs/fit
  cp runs/fit/fit.json "$out/fit.json"
fi
if [ "$mode" = profile ]; then
  timed simulate_cprofile python3 -m cProfile -o "$out/simulate.prof" -m warptissue.cli \
    simulate scenes/liver_fit.toml --device cuda --quiet --out runs/sim3
  stats "$out/simulate.prof"
  timed fit_cprofile python3 -m cProfile -o "$out/fit.prof" -m warptissue.cli \
    fit indentation scenes/liver_fit.toml --device cuda --quiet --out runs/fit3
  stats "$out/fit.prof"
fi
if [ "$mode" = time ]; then
  # the main job with every factorization fresh (no GMRES with old factors)
  timed fit_no_reuse "${cli[@]}" fit indentation scenes/liver_fit_fresh.toml --device cuda --quiet --out runs/fitnr
  cp runs/fitnr/fit.json "$out/fit_no_reuse.json"
fi
if [ "$mode" = batch ]; then
  timed batch_fits python3 scripts/benchmarks/bench_batch_fe.py --device cuda --tets 1.3k \
    --what fits --counts 1,8,32,128 --sequential-limit 2 --label "$label" --out "$out/batch_fits.json"
  timed batch_cprofile python3 -m cProfile -o "$out/batch32.prof" \
    scripts/benchmarks/bench_batch_fe.py --device cuda --tets 1.3k --what fits --counts 32 \
    --sequential-limit 1 --label "$label"
  stats "$out/batch32.prof"
  # the K tangents' factorization at the batched fits' size: block-diagonal cuDSS, batch API,
  # a loop, and the dense batched LU of cuSOLVER (through CuPy)
  timed cudss_batch python3 scripts/benchmarks/bench_cudss_batch.py --tets 1.3k \
    --counts 1,8,32,128 --dense-limit-gib 40 --label "$label" --out "$out/cudss_batch_1k.json"
fi
if [ "$mode" = cluster ]; then  # the same 32 fits: batched on the GPU, and on 16 warm CPU workers
  timed cluster python3 scripts/benchmarks/bench_batch_fe.py --device cuda --tets 1.3k \
    --what fits --counts 32 --sequential-limit 1 --cluster-workers 16 --label "$label" \
    --out "$out/batch_cluster.json"
fi
if [ "$mode" = equality ]; then  # this host's CPU against the GPU, each run here
  # (every call starts with an empty $OUT and a fresh work folder: nothing of "time" is left)
  timed simulate_cuda "${cli[@]}" simulate scenes/liver_fit.toml --device cuda --quiet --out runs/simcuda
  timed fit_cuda "${cli[@]}" fit indentation scenes/liver_fit.toml --device cuda --quiet --out runs/fitcuda
  cp runs/simcuda/result.json "$out/simulate_cuda_result.json"
  cp runs/fitcuda/fit.json "$out/fit.json"
  timed simulate_cpu "${cli[@]}" simulate scenes/liver_fit.toml --device cpu --quiet --out runs/simcpu
  timed fit_cpu "${cli[@]}" fit indentation scenes/liver_fit.toml --device cpu --quiet --out runs/fitcpu
  cp runs/simcpu/result.json "$out/simulate_cpu_result.json"
  cp runs/fitcpu/fit.json "$out/fit_cpu.json"
  python3 - "$out" > "$out/equality.json" <<'PY'
import json, sys
from pathlib import Path
out = Path(sys.argv[1])
def forces(name):
    data = json.loads((out / name).read_text())
    return data["force_curve"]["reaction_force_N"]
row = {}
try:
    gpu, cpu = forces("simulate_cuda_result.json"), forces("simulate_cpu_result.json")
    scale = max(abs(f) for f in cpu)
    row["force_max_rel_difference"] = max(abs(a - b) for a, b in zip(gpu, cpu)) / scale
except (OSError, KeyError, ValueError) as exc:
    row["force_error"] = repr(exc)
try:
    gpu = json.loads((out / "fit.json").read_text())["parameters"]
    cpu = json.loads((out / "fit_cpu.json").read_text())["parameters"]
    row["parameter_rel_difference"] = {
        k: abs(gpu[k]["value"] / cpu[k]["value"] - 1.0) for k in cpu if cpu[k]["value"]
    }
except (OSError, KeyError, ValueError) as exc:
    row["parameter_error"] = repr(exc)
print(json.dumps(row, indent=1))
PY
  cat "$out/equality.json"
fi
if [ "$mode" = suite ]; then  # the fast suite on this machine's CPU and GPU, 14 processes
  suite=/tmp/suite-$label
  rm -rf "$suite" && cp -r "$here/../.." "$suite" && ln -sfn ../kernels "$suite/warptissue/kernels"
  mkdir -p /tmp/bin && printf '#!/bin/sh\nexec python3 -m warptissue.cli "$@"\n' > /tmp/bin/warptissue
  chmod +x /tmp/bin/warptissue
  cd "$suite" || exit 1
  PYTHONPATH="$suite:/tmp/site" PATH="/tmp/bin:$PATH" timed suite python3 -m pytest -n 14 -q \
    -p no:cacheprovider -o addopts='-ra -m "not slow"' --durations=15 tests
  tail -40 "$out/suite.log"
fi
cat "$out/walls.txt"
