"""Every case of the hostile-input corpus: the right exit code, one clean line, nothing lost, nothing left.

The corpus (``corpus.py``) is generated here, in a temporary folder: damaged and
crafted photos, absurd numbers for every subcommand and the Python API, outputs
over the user's files, SIGKILL during a write. Each case runs in its own
subprocess with a time limit; a case that is not ``ok`` fails with its outcome
(hang, internal error, file lost or overwritten, leftovers, wrong exit code,
noisy stderr) and the reason. ``benchmarks/hostile_corpus.py`` counts the
outcomes, the slow cases included.
"""

from __future__ import annotations

import pytest

from hostile.corpus import build_cases, generate_inputs, run_cases

CASES = {case.name: case for case in build_cases()}

#: Cases run at once (each is a subprocess; the CI machine has 2 cores).
JOBS = 2


@pytest.fixture(scope="module")
def outcomes(request, tmp_path_factory):
    """The outcome of every case selected for this session, run ``JOBS`` at a time."""
    selected = [item.callspec.params["name"] for item in request.session.items
                if getattr(item, "originalname", None) == "test_hostile_case"]
    inputs = generate_inputs(tmp_path_factory.mktemp("hostile") / "inputs")
    return run_cases([CASES[name] for name in selected], inputs, tmp_path_factory.mktemp("cases"), JOBS)


@pytest.mark.parametrize("name", list(CASES))
def test_hostile_case(outcomes, name):
    outcome = outcomes[name]
    assert outcome.outcome == "ok", f"{name}: {outcome.outcome}: {outcome.detail}\nstderr: {outcome.stderr[-600:]}"


def test_corpus_covers_every_subcommand_and_class():
    """The corpus reaches every subcommand and every kind of hostile input the issue lists."""
    from bokehfit.cli import SUBCOMMANDS

    commands = {case.argv[0] for case in CASES.values() if case.argv}
    assert {module.__name__.rsplit(".", 1)[1] for module in SUBCOMMANDS} <= commands
    groups = {case.group for case in CASES.values()}
    assert {"metadata", "huge", "damaged", "numeric", "outputs", "api", "valid"} <= groups
    assert any(case.kill for case in CASES.values()) and any(case.foreign for case in CASES.values())
