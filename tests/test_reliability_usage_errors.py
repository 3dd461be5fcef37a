"""Usage errors in one style (issue 53): a bad option value or argument is one line
``error: OPTION: what is wrong``, never labelled "invalid spec" when no spec is at fault
(before: `fleet trends` on an empty folder said "error: invalid spec: RESULTS: …", as did a
bad --threshold, `stiffness --planet 9` and a view that needs the gearbox)."""

from __future__ import annotations

import numpy as np
import pytest
from _cli_errors import one_error_line


@pytest.mark.parametrize("argv,option", [
    (["fleet", "trends", "{d}"], "RESULTS"),
    (["fleet", "table", "{d}"], "RESULTS"),
    (["fleet", "trends", "{d}", "--threshold", "bogus"], "--threshold"),
    (["stiffness", "--preset", "paper-bench", "--planet", "9"], "--planet"),
    (["stiffness", "--preset", "paper-bench", "--fault", "planet:7:crack:0.3"], "--fault"),
    (["view", "{d}/r.csv", "--kind", "order"], "--preset/--spec"),
])
def test_option_errors_name_the_option_not_the_spec(argv, option, tmp_path, capsys):
    t = np.arange(5000) / 5000.0
    np.savetxt(tmp_path / "r.csv", np.column_stack([t, np.sin(2 * np.pi * 50 * t)]),
               delimiter=",", header="time [s],acc [m/s^2]", comments="")
    line = one_error_line([a.replace("{d}", str(tmp_path)) for a in argv], capsys)
    assert line.startswith(f"error: {option}: "), line
    assert "invalid spec" not in line, line


def test_a_missing_text_option_names_what_it_accepts(tmp_path, capsys):
    """`dtwin view FILE` without --kind: the kinds, not "accepted: text"."""
    line = one_error_line(["view", str(tmp_path / "r.csv")], capsys)
    assert line.startswith("error: --kind: missing (accepted: order, tsa, envelope, kurtogram, "
                           "cepstrum, waterfall or psd; see dtwin view --help)"), line
