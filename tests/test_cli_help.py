"""Help texts list what the code accepts: every registered integrator where integrators are offered,
and every name a help text offers is accepted."""

from __future__ import annotations

import re

import pytest

from granchain.cli import SUBCOMMANDS, main
from granchain.solve.integrators import INTEGRATORS


def help_text(capsys, command: str) -> str:
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    return " ".join(capsys.readouterr().out.split())  # argparse wraps lines: compare on single spaces


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_every_subcommand_has_help(capsys, command):
    assert help_text(capsys, command)


@pytest.mark.parametrize("command", ["pulse", "ensemble"])
def test_integrator_choices_are_the_registry(capsys, command):
    text = help_text(capsys, command)
    choices = re.search(r"--integrator \{([a-z0-9,]+)\}", text)
    assert choices, text
    assert set(choices.group(1).split(",")) == set(INTEGRATORS)


def test_pulse_lists_every_integrator_and_what_each_setting_applies_to(capsys):
    text = help_text(capsys, "pulse")
    for name in INTEGRATORS:
        assert re.search(rf"\b{name}\b", text.split("--integrator", 2)[-1]), name
    assert "time step (verlet)" in text and "relative tolerance (dop853, dp5, rkn4)" in text


@pytest.mark.parametrize("name", sorted(INTEGRATORS))
def test_pulse_accepts_every_integrator_it_lists(capsys, name):
    code = main(["pulse", "--radii", "1,1,1", "--integrator", name, "--json"])
    assert code == 0, capsys.readouterr().err


def test_the_settings_go_where_the_help_says(capsys):
    """--dt is Verlet's, --rtol the adaptive methods': the other way round is refused with the reason."""
    assert main(["pulse", "--radii", "1,1,1", "--integrator", "verlet", "--dt", "0.01", "--json"]) == 0
    capsys.readouterr()
    assert main(["pulse", "--radii", "1,1,1", "--integrator", "verlet", "--rtol", "1e-6"]) == 2
    assert "verlet does not take ['rtol']" in capsys.readouterr().err
