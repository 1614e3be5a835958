#!/usr/bin/env bash
# The cosseratbench suite's experiments for cosserat and PyElastica, scored by the suite.
#
#   scripts/cosseratbench.sh [EXPERIMENT ...]     # default: all seven
#
# Installs cosseratbench 0.3.0 and pyelastica into a venv ($VENV, default .venv at the
# repository root) unless it is there, builds the release binary, and for each experiment
# at the suite's default variant and resolution:
#   1. `cosseratbench run EXPERIMENT -s pyelastica`: the suite writes the variant's
#      experiment.json and runs PyElastica (a saved run that still stands is reused);
#   2. scripts/cosseratbench_scene.py writes the matching cosserat scene (see its header
#      for the translation) and gives the suite's scenario digest and frame spacing;
#   3. `cosserat run SCENE --cosseratbench ...` writes cosseratbench/ (docs/outputs.md,
#      "The cosseratbench layout"), copied to the variant's cosserat/ folder;
#   4. `cosseratbench rescore` scores it from its trajectory, like the suite's own runs;
# then prints per experiment and solver: outcome, metrics, wall time.
# Results in $RESULTS (default out/cosseratbench). Not run in CI (minutes to tens of
# minutes); runs one at a time, so wall times are comparable.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
venv=${VENV:-$root/.venv}
results=${RESULTS:-$root/out/cosseratbench}
target=${CARGO_TARGET_DIR:-$root/target}
if [ $# -gt 0 ]; then
  experiments=("$@")
else
  experiments=(cantilever catenary pendulum capstan crossing twist pile)
fi

if [ ! -x "$venv/bin/cosseratbench" ] || ! "$venv/bin/python" -c "import elastica" 2>/dev/null; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet cosseratbench==0.3.0 pyelastica
fi
cargo build --release --quiet --bin cosserat
bin=$target/release/cosserat
mkdir -p "$results"

for e in "${experiments[@]}"; do
  echo "== $e"
  "$venv/bin/cosseratbench" run "$e" -s pyelastica -o "$results"
  dir=$results/$e/default
  if ! read -r digest output_dt < <("$venv/bin/python" scripts/cosseratbench_scene.py "$e" "$dir/cosserat.toml"); then
    echo "$e: no cosserat scene (see the error above)"
    continue
  fi
  rm -rf "$dir/cosserat" "$dir/cosserat-run"
  # A run that fails still writes cosseratbench/ (outcome "diverged"); go on.
  "$bin" run "$dir/cosserat.toml" --out "$dir/cosserat-run" --output-dt "$output_dt" \
    --cosseratbench --experiment-json "$dir/experiment.json" --scenario-digest "$digest" \
    >"$dir/cosserat-run.log" 2>&1 || echo "$e: cosserat run failed (exit $?): $(tail -1 "$dir/cosserat-run.log")"
  if [ -d "$dir/cosserat-run/cosseratbench" ]; then
    cp -r "$dir/cosserat-run/cosseratbench" "$dir/cosserat"
  fi
done

"$venv/bin/cosseratbench" rescore -r "$results" "${experiments[@]}"

"$venv/bin/python" - "$results" "$("$bin" --version)" "$(git rev-parse --short HEAD 2>/dev/null || echo unknown)" "${experiments[@]}" <<'EOF'
import json, os, sys, time
from importlib.metadata import version
from pathlib import Path

results, binary, commit, names = Path(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4:]
print()
print(
    f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {binary} ({commit}), "
    f"cosseratbench {version('cosseratbench')}, pyelastica {version('pyelastica')}; "
    f"load average {os.getloadavg()[0]:.1f} at the end"
)
print()
print("| experiment (n) | solver | outcome | metrics | wall s |")
print("|---|---|---|---|---|")
for name in names:
    for solver in ("cosserat", "pyelastica"):
        path = results / name / "default" / solver / "result.json"
        if not path.exists():
            print(f"| {name} | {solver} | not run | | |")
            continue
        r = json.loads(path.read_text())
        metrics = ", ".join(
            f"{k} {v:.3g}" if v is not None else f"{k} n/a" for k, v in r["metrics"].items()
        )
        if r["outcome"] == "diverged":
            at = r.get("diverged_at")
            metrics = f"at t = {at:.3g}: {r['failure']}" if at is not None else r["failure"]
        wall = f"{r['wall_time']:.3g}" if r.get("wall_time") is not None else ""
        print(f"| {name} ({r['n_elements']}) | {solver} | {r['outcome']} | {metrics} | {wall} |")
EOF
