"""Component validation: bad values raise ValidationError naming the field; good ones normalise."""

from __future__ import annotations

import math

import pytest

from components import ABERRATION_EXITS, ABERRATION_MODES, Aberration, Camera, Mesh, Name, Portal, Transform
from components.validation import ValidationError
from engine.settings import Settings


def field_of(excinfo: pytest.ExceptionInfo[ValidationError]) -> str:
    return excinfo.value.field


# --- Transform -----------------------------------------------------------------


def test_transform_defaults_are_identity():
    t = Transform()
    assert t.position == (0.0, 0.0, 0.0)
    assert t.rotation == (0.0, 0.0, 0.0, 1.0)
    assert t.scale == (1.0, 1.0, 1.0)


def test_transform_normalises_to_float_tuples():
    t = Transform([1, 2, 3], [0, 0, 0, 1], [2, 2, 2])
    assert t.position == (1.0, 2.0, 3.0)
    assert all(isinstance(c, float) for c in (*t.position, *t.rotation, *t.scale))
    assert isinstance(t.position, tuple) and isinstance(t.rotation, tuple) and isinstance(t.scale, tuple)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_zero_scale_names_the_component(axis):
    scale = [1.0, 1.0, 1.0]
    scale[axis] = 0.0
    with pytest.raises(ValidationError) as e:
        Transform(scale=tuple(scale))
    assert field_of(e) == f"scale[{axis}]"
    assert "zero" in e.value.message


def test_negative_scale_is_allowed():
    assert Transform(scale=(-1.0, 1.0, 1.0)).scale == (-1.0, 1.0, 1.0)


def test_non_unit_quaternion_is_rejected():
    with pytest.raises(ValidationError) as e:
        Transform(rotation=(0.0, 0.0, 0.0, 2.0))
    assert field_of(e) == "rotation"
    assert "unit length" in e.value.message


def test_nearly_unit_quaternion_is_accepted():
    assert Transform(rotation=(0.0, 0.0, 0.0, 1.00001)).rotation[3] == 1.00001


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_position_names_the_index(bad):
    with pytest.raises(ValidationError) as e:
        Transform(position=(0.0, bad, 0.0))
    assert field_of(e) == "position[1]"


@pytest.mark.parametrize(
    ("value", "field"),
    [("abc", "position"), ((1.0, 2.0), "position"), ((1.0, "x", 3.0), "position[1]"), ((True, 0, 0), "position[0]")],
)
def test_wrong_types_in_vectors(value, field):
    with pytest.raises(ValidationError) as e:
        Transform(position=value)
    assert field_of(e) == field


def test_transform_is_frozen():
    with pytest.raises(AttributeError):
        Transform().position = (1.0, 1.0, 1.0)  # type: ignore[misc]  # the assignment the types forbid, tried


# --- Camera ------------------------------------------------------------------------


def test_camera_defaults_and_floats():
    c = Camera(fov_deg=90, speed=2)
    assert c.fov_deg == 90.0 and isinstance(c.fov_deg, float)
    assert c.speed == 2.0 and isinstance(c.speed, float)


@pytest.mark.parametrize(("kwargs", "field"), [({"fov_deg": 0.0}, "fov_deg"), ({"fov_deg": 180.0}, "fov_deg"),
                                               ({"fov_deg": math.nan}, "fov_deg"), ({"speed": 0.0}, "speed"),
                                               ({"speed": -1.0}, "speed"), ({"speed": "fast"}, "speed")])  # fmt: skip
def test_camera_rejects(kwargs, field):
    with pytest.raises(ValidationError) as e:
        Camera(**kwargs)
    assert field_of(e) == field


# --- Mesh ----------------------------------------------------------------------------


def test_mesh_normalises_colour_and_checker():
    m = Mesh("box", color=[1, 0, 0], checker=1)
    assert m.color == (1.0, 0.0, 0.0) and isinstance(m.color, tuple)
    assert m.checker == 1.0 and isinstance(m.checker, float)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"asset": ""}, "asset"),
        ({"asset": 3}, "asset"),
        ({"asset": "box", "color": (1.5, 0.0, 0.0)}, "color[0]"),
        ({"asset": "box", "color": (0.0, 0.0, -0.1)}, "color[2]"),
        ({"asset": "box", "color": (0.0, math.nan, 0.0)}, "color[1]"),
        ({"asset": "box", "checker": -1.0}, "checker"),
        ({"asset": "box", "cull_backfaces": 1}, "cull_backfaces"),
    ],
)
def test_mesh_rejects(kwargs, field):
    with pytest.raises(ValidationError) as e:
        Mesh(**kwargs)
    assert field_of(e) == field


# --- Aberration ----------------------------------------------------------------------


def test_aberration_defaults():
    a = Aberration()
    assert a.mode == "metric" and a.exit == "restore" and a.deformation == (0.0, 0.0, 0.0)
    assert set(ABERRATION_MODES) == {"metric", "radial", "additive"}
    assert set(ABERRATION_EXITS) == {"restore", "repeat", "invert"}


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("d", [-1.0, -1.5])
def test_metric_deformation_at_or_below_minus_one(axis, d):
    deformation = [0.0, 0.0, 0.0]
    deformation[axis] = d
    with pytest.raises(ValidationError) as e:
        Aberration(deformation=tuple(deformation))
    assert field_of(e) == f"deformation[{axis}]"
    assert "> -1" in e.value.message


def test_metric_deformation_just_above_minus_one_is_fine():
    assert Aberration(deformation=(-0.999, 0, 2)).deformation == (-0.999, 0.0, 2.0)


def test_radial_and_additive_allow_any_finite_deformation():
    assert Aberration(deformation=(-3.0, 0.0, 0.0), mode="radial").deformation[0] == -3.0
    assert Aberration(deformation=(-3.0, 0.0, 0.0), mode="additive").deformation[0] == -3.0


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"mode": "warp"}, "mode"),
        ({"exit": "bounce"}, "exit"),
        ({"priority": 1.5}, "priority"),
        ({"priority": True}, "priority"),
        ({"debug_draw": "yes"}, "debug_draw"),
        ({"color": (0.0, 2.0, 0.0)}, "color[1]"),
        ({"deformation": (0.0, math.nan, 0.0)}, "deformation[1]"),
        ({"deformation": (0.0, 0.0)}, "deformation"),
    ],
)
def test_aberration_rejects(kwargs, field):
    with pytest.raises(ValidationError) as e:
        Aberration(**kwargs)
    assert field_of(e) == field


def test_bad_mode_lists_the_options():
    with pytest.raises(ValidationError) as e:
        Aberration(mode="warp")
    for mode in ABERRATION_MODES:
        assert mode in e.value.message


# --- Portal, Name, Settings --------------------------------------------------------------


def test_portal_target_may_be_none_or_a_name():
    assert Portal().target is None
    assert Portal("other").target == "other"
    assert Portal(color=[0, 1, 0]).color == (0.0, 1.0, 0.0)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [({"target": ""}, "target"), ({"target": 5}, "target"), ({"color": (2.0, 0, 0)}, "color[0]"),
     ({"debug_draw": None}, "debug_draw")],
)  # fmt: skip
def test_portal_rejects(kwargs, field):
    with pytest.raises(ValidationError) as e:
        Portal(**kwargs)
    assert field_of(e) == field


@pytest.mark.parametrize("bad", ["", "   ", None, 3])
def test_name_rejects(bad):
    with pytest.raises(ValidationError) as e:
        Name(bad)
    assert field_of(e) == "name"


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"background": (1.0, 1.0, 1.1)}, "background[2]"),
        ({"light_dir": (0.0, 0.0, 0.0)}, "light_dir"),
        ({"max_events": 0}, "max_events"),
        ({"max_events": 2.0}, "max_events"),
        ({"event_limit_color": (0.0, -1.0, 0.0)}, "event_limit_color[1]"),
        ({"ambient": 1.5}, "ambient"),
    ],
)
def test_settings_rejects(kwargs, field):
    with pytest.raises(ValidationError) as e:
        Settings(**kwargs)
    assert field_of(e) == field


def test_validation_error_nests_under_a_prefix():
    e = ValidationError("color[0]", "too bright").within("mesh")
    assert e.field == "mesh.color[0]"
    assert str(e) == "mesh.color[0]: too bright"
