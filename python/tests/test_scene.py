"""Scenes: built-in, file and text round trips, `set` with the checks of `--set`, errors."""

import pytest

import cosserat
from conftest import ROOT


def test_builtin_names_and_attributes():
    assert "frame" in cosserat.builtin_scenes()
    s = cosserat.Scene.builtin("frame")
    assert s.source == "builtin:frame"
    assert s.name == "frame"
    assert s.scheme == "edmc2"
    assert s.dt == 0.2 and s.t_end == 10.0
    assert s.nodes > 0 and s.elements > 0
    assert "frame" in repr(s)


def test_file_text_and_builtin_round_trip():
    b = cosserat.Scene.builtin("frame")
    f = cosserat.Scene.load(ROOT / "scenes" / "frame.toml")
    t = cosserat.Scene.from_toml(b.text, source="frame.toml")
    for s in (f, t):
        assert (s.nodes, s.elements, s.dt, s.t_end, s.scheme) == (
            b.nodes,
            b.elements,
            b.dt,
            b.t_end,
            b.scheme,
        )
        assert s.text == b.text
    assert f.source.endswith("frame.toml")
    assert str(b.elements) in b.check()


def test_set_writes_values_with_the_checks_of_dash_dash_set():
    s = cosserat.Scene.builtin("cantilever")
    s.set("integrator.dt", 0.02)
    s.set("rod[0].elements", 10)
    assert s.dt == 0.02
    assert s.elements == 10
    assert s.sets == [("integrator.dt", 0.02), ("rod[0].elements", 10.0)]
    c = s.copy()
    c.set("integrator.t_end", 1.0)
    assert (c.t_end, s.t_end) == (1.0, 10.0)


def test_invalid_value_raises_scene_error_naming_key_and_keeps_the_scene():
    s = cosserat.Scene.builtin("frame")
    with pytest.raises(cosserat.SceneError) as e:
        s.set("integrator.dt", -0.1)
    assert isinstance(e.value, ValueError)
    assert "integrator.dt" in str(e.value)
    assert e.value.key == "integrator.dt"
    assert e.value.file == "builtin:frame"
    assert e.value.reason
    assert s.dt == 0.2 and s.sets == []


def test_unknown_key_path_is_a_scene_error():
    s = cosserat.Scene.builtin("frame")
    with pytest.raises(cosserat.SceneError, match="no_such_table"):
        s.set("no_such_table.x", 1.0)


def test_syntax_error_gives_line_and_column():
    with pytest.raises(cosserat.SceneError) as e:
        cosserat.Scene.from_toml("name = 'x'\n[integrator\n", source="bad.toml")
    assert str(e.value).startswith("bad.toml:2:")
    assert e.value.line == 2 and e.value.file == "bad.toml"


def test_missing_file_and_unknown_builtin():
    with pytest.raises(cosserat.SceneError, match="no/such/scene.toml"):
        cosserat.Scene.load("no/such/scene.toml")
    with pytest.raises(cosserat.SceneError, match="frame"):
        cosserat.Scene.builtin("no-such-scene")
