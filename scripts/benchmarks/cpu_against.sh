#!/usr/bin/env bash
# The CPU no slower than an earlier commit (issue 46): the main job's fit and the flat-punch
# curve, alternating between two checkouts, in one run on one machine.
#
#   bash scripts/benchmarks/cpu_against.sh OLD_CHECKOUT NEW_CHECKOUT ROUNDS OUT_DIR
#
# Each checkout runs with its own Python (CHECKOUT/.venv/bin/python, an editable install;
# /work/venv style environments work too: set OLD_PYTHON / NEW_PYTHON). Per round: the main
# job (`fit indentation scenes/liver_fit.toml --device cpu`, fit.json `seconds`) and
# `bench_flat_punch.py --device cpu --mesher delaunay --sizes 3k` (its `solve_s`), old then
# new, then new then old in the next round. Writes OUT_DIR/cpu_against.json.
set -euo pipefail
old=$(cd "$1" && pwd) new=$(cd "$2" && pwd) rounds=$3 out=$(mkdir -p "$4" && cd "$4" && pwd)
old_python=${OLD_PYTHON:-$old/.venv/bin/python} new_python=${NEW_PYTHON:-$new/.venv/bin/python}
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}
one() {  # which round: the main job and the punch of one checkout
  local which=$1 round=$2 root python
  if [ "$which" = old ]; then root=$old python=$old_python; else root=$new python=$new_python; fi
  local dir="$out/$which-$round"
  rm -rf "$dir" && mkdir -p "$dir"
  (cd "$root" && "$python" -m warptissue.cli fit indentation scenes/liver_fit.toml --device cpu \
    --quiet --out "$dir/fit" > "$dir/fit.log" 2>&1)
  (cd "$root" && "$python" scripts/benchmarks/bench_flat_punch.py --device cpu --mesher delaunay \
    --sizes 3k --felupe-levels "" --felupe-axisymmetric-levels "" --out "$dir/punch.json" \
    > "$dir/punch.log" 2>&1)
}
for round in $(seq 1 "$rounds"); do
  if [ $((round % 2)) = 1 ]; then one old "$round"; one new "$round"; else one new "$round"; one old "$round"; fi
done
python3 - "$out" "$rounds" "$old" "$new" <<'PY'
import json, subprocess, sys
from pathlib import Path
out, rounds, old, new = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
def commit(root):
    return subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
def punch_seconds(path):
    runs = json.loads(path.read_text())["runs"]
    return [(run["solve_s"], run["newton_iterations"]) for run in runs]
table = {"old": {"commit": commit(old)}, "new": {"commit": commit(new)}}
for which in ("old", "new"):
    fits, punches, c10 = [], [], []
    for r in range(1, rounds + 1):
        fit = json.loads((out / f"{which}-{r}" / "fit" / "fit.json").read_text())
        fits.append(fit["seconds"])
        c10.append(fit["parameters"]["C10_Pa"]["value"])
        punches.append(punch_seconds(out / f"{which}-{r}" / "punch.json"))
    table[which].update(fit_seconds=fits, c10_Pa=c10, punch_seconds=punches)
json.dump(table, open(out / "cpu_against.json", "w"), indent=2)
print(json.dumps(table, indent=2))
PY
