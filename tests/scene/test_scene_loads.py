"""``Scene.loads(text)``: a scene from TOML text, with :meth:`Scene.load`'s checks and messages."""

from __future__ import annotations

from pathlib import Path

import pytest

from couplekit.scene import Scene, SceneError

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "sand_drop_small.toml"


def test_loads_gives_the_scene_load_gives():
    text = EXAMPLE.read_text(encoding="utf-8")
    # base_dir: the scene's relative files (none here) would resolve as load resolves them
    assert Scene.loads(text, base_dir=EXAMPLE.parent) == Scene.load(EXAMPLE)


def test_loads_refuses_like_load_naming_the_string_or_the_given_name(tmp_path):
    bad = "[scene]\nname = 1\n[domain]\nsize = [0.1, 0.1, 0.1]\ndx = 0.01\n[time]\ndt = 1e-4\n[fluid]\n"
    path = tmp_path / "bad.toml"
    path.write_text(bad)
    with pytest.raises(SceneError) as from_file:
        Scene.load(path)
    with pytest.raises(SceneError) as from_text:
        Scene.loads(bad)
    with pytest.raises(SceneError) as named:
        Scene.loads(bad, name="my scene")
    assert from_text.value.problems == from_file.value.problems  # the same checks, the same messages
    assert str(from_text.value).startswith("<string> is invalid")
    assert str(named.value).startswith("my scene is invalid")
    assert str(from_file.value) == str(from_text.value).replace("<string>", str(path), 1)


def test_loads_refuses_text_that_is_not_toml_or_not_a_str():
    with pytest.raises(SceneError) as syntax:
        Scene.loads("[scene\nname = 'x'")
    assert syntax.value.keys == ["(syntax)"] and "<string>" in str(syntax.value)
    with pytest.raises(SceneError) as not_str:
        Scene.loads(b"[scene]")  # type: ignore[arg-type]
    assert not_str.value.keys == ["(file)"] and "decode" in str(not_str.value)
