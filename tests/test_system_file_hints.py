"""What a new user meets first in a system file (issue 51): a TOML error in an inline table spread over lines gets a
hint naming the sub-table to write instead, and ``uav-el fit-gate`` fits the gate ``[monitor] gate`` names before
that file exists, while every other command still refuses a system whose gate is missing."""

import pytest

from assurance import cli
from assurance.system.loader import SystemFileError, parse_system, toml_hint

SPREAD = """format = "uav-el-system/1"
[model]
path = "net.onnx"
class_map = { "ground" = "dirt", "plants" = "grass",
              "house" = "roof" }
"""


def test_an_inline_table_over_two_lines_gets_a_hint_naming_the_sub_table():
    with pytest.raises(SystemFileError) as err:
        parse_system(SPREAD, label="uav-el.toml")
    line = str(err.value)
    assert line.startswith("uav-el.toml: not valid TOML: ") and "(at line 4," in line
    assert line.endswith("an inline table { ... } must fit on one line; use a [model.class_map] table instead")
    assert "\n" not in line


@pytest.mark.parametrize("text", [
    'x = = 1\n',                                            # another error: no hint
    '[odd]\nname = "a { in a string",\nb = 1\n',           # a brace inside a string opens nothing
    '[odd]\nperturbations = { fog = 3 }\nb = = 2\n',        # the table closed on its line; the error is elsewhere
])
def test_other_errors_get_no_hint(text):
    with pytest.raises(SystemFileError) as err:
        parse_system(text, label="uav-el.toml")
    assert "inline table" not in str(err.value)


def test_a_key_set_twice_is_named():
    with pytest.raises(SystemFileError) as err:
        parse_system('format = "uav-el-system/1"\n[odd]\nheight_m = [10, 60]\nheight_m = [10, 70]\n',
                     label="uav-el.toml")
    assert str(err.value).endswith(": odd.height_m is set twice (once is allowed)"), str(err.value)


def test_hint_names_the_table_from_its_header_and_key():
    text = "[odd]\nperturbations = { fog = 3 # a comment {\n"
    assert toml_hint(text, "Unclosed inline table (at line 2, column 20)").endswith(
        "use a [odd.perturbations] table instead")
    assert toml_hint(text, "no position given") == ""
    assert toml_hint(text, "Unclosed inline table (at line 9, column 1)") == ""  # past the end: no guess


def _system(tmp_path):
    path = tmp_path / "uav-el.toml"
    path.write_text('format = "uav-el-system/1"\n[monitor]\ngate = "gate.json"\n[data]\ntrain = "train"\nval = "val"\n')
    return path


def test_fit_gate_may_write_the_gate_the_system_file_names(tmp_path, capsys):
    path = _system(tmp_path)
    assert cli.main(["fit-gate", "--system", str(path), "--out", str(tmp_path / "gate.json"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "no such folder" in err and "monitor.gate" not in err  # it got past the system file, to the data


@pytest.mark.parametrize("command", [["land", "frame.png"], ["preview", "--out", "p.png"]])
def test_other_commands_still_refuse_a_missing_gate(tmp_path, capsys, command):
    path = _system(tmp_path)
    assert cli.main([*command, "--system", str(path)]) == 2
    assert "monitor.gate: " in capsys.readouterr().err


def test_fit_gate_still_refuses_something_that_is_not_a_file_at_the_gate(tmp_path, capsys):
    path = _system(tmp_path)
    (tmp_path / "gate.json").mkdir()
    assert cli.main(["fit-gate", "--system", str(path), "--out", str(tmp_path / "g.json"), "--no-progress"]) == 2
    assert "monitor.gate: " in capsys.readouterr().err


def test_calibrate_may_write_the_card_the_system_file_names(tmp_path, capsys):
    path = tmp_path / "uav-el.toml"
    path.write_text('format = "uav-el-system/1"\n[monitor]\nspec = "lhd"\ncalibration = "card.json"\n'
                    '[data]\ntrain = "train"\nval = "val"\n')
    assert cli.main(["calibrate", "--system", str(path), "--out", str(tmp_path / "card.json"), "--miss-rate",
                     "0.8"]) == 2
    err = capsys.readouterr().err
    assert "no such folder" in err and "monitor.calibration" not in err  # past the system file, to the data
    assert cli.main(["land", "frame.png", "--system", str(path)]) == 2  # any other command still refuses it
    assert "monitor.calibration: " in capsys.readouterr().err
