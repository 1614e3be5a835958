#!/usr/bin/env bash
# Mutation check (docs/testing.md, "Mutation check"): cargo-mutants on the element kernel
# (default) or the integrator, with the fast physics tests.
#
#   scripts/mutants.sh element [K N]      # src/element/, shard K of N (default 0 1: all)
#   scripts/mutants.sh integrator [K N]   # src/integrator/
#
# Needs cargo-mutants (`cargo install cargo-mutants --locked`) and, for the GPU parity
# tests, a Vulkan adapter (lavapipe works). Every mutant rebuilds the crate and its test
# targets (≈ 25 s with the `mutants` profile of Cargo.toml on the 2-core CI machine) and
# runs the tests (≈ 40–90 s), so the full sets (≈ 1 800 mutants in src/element/, ≈ 2 200 in
# src/integrator/) take days there; a shard `K N` runs every N-th mutant (round-robin), a
# uniform sample. Results go to $MUTANTS_OUT/mutants.out/ (default: the repository root;
# outcomes.json, caught.txt, missed.txt, unviable.txt, timeout.txt).
set -euo pipefail
cd "$(dirname "$0")/.."
set_name=${1:-element}
shard=${2:-0}
n=${3:-1}
case "$set_name" in
element)
    files=(src/element/mod.rs src/element/strain.rs src/element/dissipation.rs
        src/element/director_factor.rs src/element/planar.rs)
    tests=(--lib --test tangent --test conservation --test planar_kernel --test gpu_kernel)
    ;;
integrator)
    files=(src/integrator/*.rs src/integrator/simulation/*.rs)
    tests=(--lib --test conservation --test tangent --test newton_variants --test fallback
        --test external_work --test cutback --test contact --test damping --test line_loads
        --test support_motion --test planar_kernel --test study)
    ;;
*)
    echo "usage: $0 element|integrator [K N]" >&2
    exit 2
    ;;
esac
args=()
for f in "${files[@]}"; do args+=(-f "$f"); done
export NODEVICE_SELECT=1
exec cargo mutants "${args[@]}" --shard "$shard/$n" --sharding round-robin \
    --profile mutants --baseline skip --timeout 600 --build-timeout 900 -j 1 \
    -o "${MUTANTS_OUT:-.}" -- "${tests[@]}"
