"""`cosserat.bench()`: the object `cosserat bench --json` prints, from the same engine call."""

import json

import pytest

import cosserat

TINY = dict(rods=2, elements=3, steps=2)


def test_bench_returns_the_json_of_the_command(cli):
    mine = cosserat.bench(**TINY, cpu_only=True)
    theirs = json.loads(
        cli("bench", "--json", "--cpu-only", "--rods", 2, "--elements", 3, "--steps", 2).stdout
    )
    assert set(mine) == set(theirs)
    # What is not a timing is equal: sizes, options, the work done.
    for key in ("rods", "elements", "steps", "newton", "strategy", "cpu_strategy", "adapter",
                "cpu_newton_iters", "cpu_failed", "cpu_factorizations", "cpu_solves"):
        assert mine[key] == theirs[key], key
    assert mine["cpu_failed"] == 0 and mine["cpu_newton_iters"] > 0
    assert mine["cpu_element_steps_per_s"] > 0 and mine["gpu_element_steps_per_s"] is None


def test_bench_options_reach_the_engine():
    r = cosserat.bench(**TINY, cpu_only=True, newton="modified", strategy="staggered")
    assert (r["newton"], r["strategy"], r["cpu_strategy"]) == ("modified", "staggered", "staggered")


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(rods=0), "rods: must be an integer ≥ 1 (got 0)"),
        (dict(elements=2_000_000), "elements: 2000000 elements per rod, above the limit"),
        (dict(newton="newest"), "newton: unknown variant `newest`"),
        (dict(cpu_only=True, gpu_only=True), "cpu_only and gpu_only exclude each other"),
    ],
)
def test_bench_refuses_bad_options(kw, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        cosserat.bench(**{**TINY, **kw})
