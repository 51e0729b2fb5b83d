"""Every transfer setting is written once (core/transfer/config.py) and reaches the command line from there."""

from __future__ import annotations

import re

import pytest

from gt2gs_blender.app.cli import main as cli
from gt2gs_blender.app.cli.options import config_from_args, flag
from gt2gs_blender.core.features.weights import PREFERENCES
from gt2gs_blender.core.render import BACKENDS
from gt2gs_blender.core.transfer.config import SETTINGS, TransferConfig, setting_type, user_settings
from gt2gs_blender.core.transfer.presets import PRESETS, preset
from gt2gs_blender.core.transfer.setting import PARTS


def transfer_help(capsys) -> str:
    assert cli.main(["transfer", "--help"]) == 0
    return capsys.readouterr().out


def test_every_setting_has_a_cli_flag_unless_internal(capsys):
    text = transfer_help(capsys)
    missing = [name for name, meta in SETTINGS.items() if not meta.internal and flag(name, meta) not in text]
    assert not missing, f"settings without a --flag in `transfer --help`: {missing}"


def test_every_setting_has_metadata_a_user_can_read():
    for name, meta in SETTINGS.items():
        assert meta.part in PARTS, name
        assert meta.label and meta.help and not meta.help.endswith("."), name
        assert meta.min is None or meta.max is None or meta.min <= meta.max, name


def test_every_presets_value_lies_in_its_settings_range():
    for preset_name, config in PRESETS.items():
        for name, meta, _ in user_settings():
            value = getattr(config, name)
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                assert meta.min is None or value >= meta.min, (preset_name, name, value)
                assert meta.max is None or value <= meta.max, (preset_name, name, value)
            if meta.choices:
                assert value in meta.choices, (preset_name, name, value)


def test_choices_are_the_engines_own():
    assert SETTINGS["backend"].choices == ("auto", *BACKENDS)
    assert SETTINGS["features"].choices == PREFERENCES


@pytest.mark.parametrize(
    "argv, expected",
    [
        ((), {}),
        (
            ("--steps", "12", "--no-gpb", "--angle", "30", "--background", "0,0.5,1"),
            {"stylise_steps": 12, "gpb": False, "angle": 30.0, "background": (0.0, 0.5, 1.0)},
        ),
        (
            ("--no-plateau-stop", "--full-matching", "--stylise-geometry", "on", "--lambda-prior", "0.01"),
            {"plateau_window": 0, "match_channels": 0, "stylise_geometry": "on", "lambda_prior": 0.01},
        ),
        (("--preset", "preview", "--weights", "w.pth", "--threads", "2"), {"weights_path": "w.pth", "threads": 2}),
    ],
)
def test_cli_options_become_the_config(argv, expected):
    parser = cli.build_parser()
    args = parser.parse_args(["transfer", "s.ply", "t.jpg", "-o", "o.ply", *argv])
    assert config_from_args(args) == PRESETS[args.preset].with_overrides(**expected)


@pytest.mark.parametrize("name", [name for name, meta in SETTINGS.items() if meta.choices])
def test_a_bogus_choice_is_refused_when_the_config_is_made(name):
    """Every choice setting, not a hand-written list of them: refused at construction, naming the allowed words."""
    allowed = re.escape(", ".join(SETTINGS[name].choices))
    with pytest.raises(ValueError, match=f"^{name} must be one of {allowed}, got 'bogus'$"):
        TransferConfig(**{name: "bogus"})


NUMBERS = [name for name, _, kind in user_settings() if kind in (int, float)]


@pytest.mark.parametrize("name", [n for n in NUMBERS if SETTINGS[n].min is not None or SETTINGS[n].max is not None])
def test_a_number_outside_its_range_is_refused_when_the_config_is_made(name):
    """Every number setting's range is its metadata's (the one Blender's properties and the help show)."""
    meta = SETTINGS[name]
    outside = meta.min - 1 if meta.min is not None else meta.max + 1
    with pytest.raises(ValueError, match=f"^{name} must be {meta.range_text()}, got "):
        TransferConfig(**{name: setting_type(name)(outside)})


@pytest.mark.parametrize("name", [n for n in NUMBERS if setting_type(n) is float])
@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_a_non_finite_number_is_refused(name, value):
    with pytest.raises(ValueError, match=f"^{name} must be a finite number"):
        TransferConfig(**{name: value})


@pytest.mark.parametrize("preset_name", list(PRESETS))
def test_a_texture_height_given_alone_is_the_size_used_in_the_api_as_in_the_cli(preset_name):
    """``texture_height`` without ``texture_repeats`` means repeats 0 (use the size), through ``preset()`` as
    through ``--texture-height``; with both given, both are kept."""
    api = preset(preset_name, texture_height=128)
    args = cli.build_parser().parse_args(["transfer", "s.ply", "t.jpg", "-o", "o.ply", "--preset", preset_name])
    args.texture_height = 128
    assert (api.texture_height, api.texture_repeats) == (128, 0.0)
    assert config_from_args(args) == api
    both = preset(preset_name, texture_height=128, texture_repeats=2.0)
    assert (both.texture_height, both.texture_repeats) == (128, 2.0)


def test_an_out_of_range_setting_is_one_user_error(capsys, tmp_path):
    code = cli.main(
        ["transfer", str(tmp_path / "s.ply"), str(tmp_path / "t.jpg"), "-o", str(tmp_path / "o.ply"), "--device", "tpu"]
    )
    assert code == 2 and "invalid choice" in capsys.readouterr().err
    with pytest.raises(ValueError, match="features must be one of"):
        TransferConfig(features="alexnet")
