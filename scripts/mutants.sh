#!/usr/bin/env bash
# Mutation check of the element kernel and the integrator (docs/testing.md, "Mutation check").
#
#   scripts/mutants.sh [SHARD] [N]     # default: shard 0 of 1 (every mutant)
#
# Needs cargo-mutants (`cargo install cargo-mutants --locked`). Every mutant rebuilds the
# library, about 40 s on the 2-core CI machine, so the full set (≈ 4 000 mutants in
# src/element/ and src/integrator/) takes days there; a shard `K N` runs every N-th mutant
# (round-robin), a uniform sample. Results go to mutants.out/ (outcomes.json, caught.txt,
# missed.txt, unviable.txt, timeout.txt).
set -euo pipefail
cd "$(dirname "$0")/.."
shard=${1:-0}
n=${2:-1}
files=(${MUTANTS_FILES:-src/element/mod.rs src/element/strain.rs src/element/dissipation.rs src/element/director_factor.rs src/element/planar.rs})
args=()
for f in "${files[@]}"; do args+=(-f "$f"); done
exec cargo mutants "${args[@]}" --shard "$shard/$n" --sharding round-robin \
    --profile mutants --baseline skip --timeout 300 --build-timeout 600 -j 1 -o "${MUTANTS_OUT:-.}" \
    -- --lib --test tangent --test conservation --test planar_kernel --test gpu_kernel
