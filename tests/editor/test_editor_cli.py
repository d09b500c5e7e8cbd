"""``aberrant editor``: clear one-line errors (exit 2) when there is no display or the scene cannot be read."""

from __future__ import annotations

import pytest

pytest.importorskip("imgui_bundle", reason="the editor extra is not installed: pip install 'aberrant[editor]'")

from aberrant.cli import main


def test_no_display_is_a_one_line_error(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["editor", "starter"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs a display" in err and "xvfb-run" in err


def test_a_scene_that_cannot_be_read_fails_before_a_window_opens(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("DISPLAY", ":424242")  # never contacted: the file fails first
    assert main(["editor", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("aberrant: error: ") and "missing.json" in err and "not found" in err
    assert main(["editor", "no-such-demo"]) == 2
    assert "neither a scene file (.json), a level module (.py) nor a demo" in capsys.readouterr().err
    level = tmp_path / "level.py"
    level.write_text("def build():\n    return None\n")
    assert main(["editor", f"{level}:build"]) == 2
    assert "level.py:build() returned NoneType, not a Scene" in capsys.readouterr().err


def test_editor_help_lists_the_subcommand(capsys):
    assert main(["--help"]) == 0
    assert "editor" in capsys.readouterr().out


def test_editor_size_is_checked_and_passed_to_the_window(monkeypatch, capsys):
    import editor.window

    monkeypatch.setenv("DISPLAY", ":424242")
    assert main(["editor", "starter", "--size", "12x"]) == 2  # before the display or the level is touched
    assert "--size must be WIDTHxHEIGHT" in capsys.readouterr().err
    opened = {}
    monkeypatch.setattr(editor.window, "display_problem", lambda: None)
    monkeypatch.setattr(editor.window, "run_editor", lambda model, **kw: opened.update(kw) or 0)
    assert main(["editor", "starter", "--size", "1280x800"]) == 0
    assert opened["size"] == (1280, 800)
