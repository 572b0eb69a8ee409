"""The report page of a result (`report.html` of identify, twin and diagnose -o), opened in a real browser;
the UFF files of `identify -o` read back by pyuff; the notebooks' `_repr_html_`.

The recordings are small simulated labs (tests/test_real_diagnose.py: a 3-storey shear building at
120 Hz, accelerometers only, a quiet lead-in, white sensor noise), so every page is built in seconds.
The shipped rigs' pages (a diagnosis takes half a minute to three minutes) are `slow`.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pytest
import pyuff

import momentid as mi
from momentid.cli import main
from momentid.core.series import Experiment
from momentid.core.structure import LabStatement
from momentid.estimation.noise import quiet_lead_in
from momentid.estimation.frf import measured_transfer
from momentid.io.recording import write_experiment

import browser
from conftest import DATA
from test_real_diagnose import MASSES, run

HEIGHTS = (0.15, 0.15, 0.15)            # m: stated storey heights (the UFF's node coordinates)
#: A trial name made of HTML: the page must show these characters, never run them as markup.
#: (no "/": a run name becomes part of file names, and the recording refuses one)
MARKUP = "<b>x<b> & <i>y"
ESCAPED = "&lt;b&gt;x&lt;b&gt; &amp; &lt;i&gt;y"


def _lab(*runs, masses=True) -> Experiment:
    statement = LabStatement(storeys=3, masses=MASSES, storey_heights=HEIGHTS) if masses else None
    return Experiment(runs=tuple(runs), statement=statement, source="sim")


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """Three trials of a linear rig with stated masses and heights, one of them named with HTML."""
    path = tmp_path_factory.mktemp("report") / "lab.mcap"
    write_experiment(path, _lab(run("r1", 0.3, 1), run(MARKUP, 0.6, 2), run("r3", 0.45, 3)))
    return path


@pytest.fixture(scope="module")
def identified(recording, tmp_path_factory):
    """``identify REC -o DIR --json``: the folder, and what stdout printed."""
    out = tmp_path_factory.mktemp("identified") / "id"
    import contextlib
    import io

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["identify", str(recording), "-o", str(out), "--json"]) == 0
    return out, json.loads(printed.getvalue())


def _sections(page: str) -> list:
    return [page.index(f'<section id="{key}">') for key in ("answer", "tables", "figures", "made")]


def _opens_cleanly(path: Path) -> browser.Load:
    """Open ``path`` in headless Chromium: no console error, no request beyond the page itself, every
    figure drawn with a size, as many as the page holds."""
    assert browser.chromium() is not None, "chromium is missing: apt-get install -y chromium (.ci/run installs it)"
    page = path.read_text(encoding="utf-8")
    load = browser.open_page(path)
    assert load.errors == [], load.errors
    assert load.requests == [path.resolve().as_uri()], load.requests
    assert "figure-missing" not in page.split("<body>")[1]
    assert len(load.figures) == page.count('<figure id="figure-') > 0
    assert all(w > 0 and h > 0 for w, h in load.figures), load.figures
    return load


def test_identify_writes_its_folder(identified, recording):
    out, printed = identified
    assert sorted(p.name for p in out.iterdir()) == [".momentid.json", "frf.uff", "identification.json", "modes.uff",
                                                     "report.html"]           # the manifest: the one output rule
    assert json.loads((out / "identification.json").read_text()) == printed     # what --json prints
    page = (out / "report.html").read_text(encoding="utf-8")
    answer, tables, figures, made = _sections(page)
    assert answer < tables < figures < made                      # the answer first, provenance last
    assert "Modes (± one standard error)" in page[answer:tables]
    assert "K (N/m)" in page[tables:figures] and "C (N s/m)" in page[tables:figures]
    # provenance: the exact command, the versions, the input's hash
    assert f"momentid identify {recording} -o {out} --json" in page[made:]
    assert hashlib.sha256(recording.read_bytes()).hexdigest() in page[made:]
    assert f"momentid {mi.__version__}" in page[made:] and "MuJoCo" in page[made:]


def test_uff_files_read_back_with_pyuff(identified, recording):
    out, printed = identified
    sets = pyuff.UFF(str(out / "modes.uff")).read_sets()
    assert [s["type"] for s in sets] == [164, 15, 55, 55, 55]
    assert sets[0]["units_code"] == 1                                                # SI
    assert np.allclose(sets[1]["z"], np.cumsum([0.0, *HEIGHTS]))                   # table, floors 1..3
    modes = sets[2:]
    # E13.5 keeps six significant digits: a relative 5e-6 at most
    assert np.allclose([m["freq"] for m in modes], printed["frequency_hz"], rtol=5e-6, atol=0)
    assert np.allclose([m["modal_damp_vis"] for m in modes], printed["damping_ratio"], rtol=5e-6, atol=0)
    shapes = np.array(printed["mode_shapes"])
    for i, m in enumerate(modes):
        assert m["mode_n"] == i + 1 and list(m["node_nums"]) == [1, 2, 3]
        assert np.allclose(m["r1"], shapes[:, i], rtol=5e-6, atol=5e-6)
        assert np.allclose(m["modal_m"], np.sum(np.array(MASSES) * shapes[:, i] ** 2), rtol=5e-6)
        assert "damping ratio: an answer" in m["id4"]
    frf = [s for s in pyuff.UFF(str(out / "frf.uff")).read_sets() if s["type"] == 58]
    experiment = mi.read_recording(recording)
    assert len(frf) == 3 * 3 * 2                                    # runs x floors x (FRF, coherence)
    k = 0
    for r in experiment.runs:
        expected = measured_transfer(r, 3, quiet_lead_in(r))
        for j in range(3):
            h, coherence = frf[k], frf[k + 1]
            k += 2
            assert h["func_type"] == 4 and coherence["func_type"] == 6
            assert h["rsp_node"] == j + 1 and h["ref_node"] == 0 and h["id2"] == f"run {r.name}"
            assert np.isclose(h["abscissa_inc"], expected.frequency[1], rtol=5e-6)
            # E20.12: thirteen significant digits
            assert np.allclose(h["data"], expected.h[:, j], rtol=1e-11, atol=1e-14)
            assert np.allclose(coherence["data"], expected.coherence[:, j], rtol=1e-11, atol=1e-14)


def test_the_same_command_writes_the_same_bytes(identified, recording):
    out, _ = identified
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main(["identify", str(recording), "-o", str(out), "--json"]) == 0
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_names_are_escaped(identified):
    out, _ = identified
    page = (out / "report.html").read_text(encoding="utf-8")
    assert MARKUP not in page and ESCAPED in page
    ids = (out / "frf.uff").read_text()
    assert f"run {MARKUP}" in ids                        # UFF is text for tools, not markup: as named


def test_reports_open_in_chromium(identified, recording, tmp_path):
    out, _ = identified
    _opens_cleanly(out / "report.html")
    twin = tmp_path / "twin"
    assert main(["twin", str(recording), "-o", str(twin)]) == 0
    _opens_cleanly(twin / "report.html")
    # a diagnosis of accelerometer-only runs without stated masses (the modal path: a second)
    rec = tmp_path / "modal.mcap"
    write_experiment(rec, _lab(run("r1", 0.3, 1), run("r2", 0.6, 2), masses=False))
    assert main(["diagnose", str(rec), "-o", str(tmp_path / "diag")]) == 0
    load = _opens_cleanly(tmp_path / "diag" / "report.html")
    before = (tmp_path / "diag" / "report.html").read_bytes()
    assert main(["diagnose", str(rec), "-o", str(tmp_path / "diag")]) == 0
    assert (tmp_path / "diag" / "report.html").read_bytes() == before        # the same bytes again
    assert len(load.figures) == 3                          # overlay, comparison, where the misfit sits
    page = (tmp_path / "diag" / "report.html").read_text(encoding="utf-8")
    answer = page[_sections(page)[0]:_sections(page)[1]]
    assert '{"' not in answer and "{&quot;" not in answer and "floor-" in answer     # places in words


def test_a_figure_that_cannot_be_drawn_is_a_note(recording, tmp_path, monkeypatch):
    from momentid.report import figures

    def broken(*args, **kwargs):
        raise ValueError("no axes today")

    monkeypatch.setattr(figures, "shapes_figure", broken)
    assert main(["identify", str(recording), "-o", str(tmp_path / "a")]) == 0
    page = (tmp_path / "a" / "report.html").read_text(encoding="utf-8")
    assert "Figure 1 could not be drawn: ValueError: no axes today" in page
    assert page.count("<svg") == 1                          # the transfer functions are still drawn

    from momentid.report import identify_page

    def no_page(*args, **kwargs):
        raise RuntimeError("no page today")

    monkeypatch.setattr(identify_page, "identification_page", no_page)
    assert main(["identify", str(recording), "-o", str(tmp_path / "b")]) == 0
    page = (tmp_path / "b" / "report.html").read_text(encoding="utf-8")
    assert "The report could not be drawn: RuntimeError: no page today" in page
    assert (tmp_path / "b" / "modes.uff").exists()          # the other files are written all the same


@pytest.mark.slow   # 13 s: an identification, a twin, a diagnosis and a per-run fit for their notebook blocks
def test_notebooks_show_the_words_of_the_page(identified, recording, tmp_path):
    from momentid.report.files import diagnosis_html_page, identification_html_page, twin_html_page
    from momentid.report.page import provenance
    from momentid.twin import build_twin

    experiment = mi.read_recording(recording)
    made = provenance(None, [recording])
    result = mi.identify(experiment)
    block = result._repr_html_()
    assert MARKUP not in block and ESCAPED in block
    assert block in identification_html_page(result, experiment, made)
    twin = build_twin(experiment)
    assert twin._repr_html_() in twin_html_page(twin, experiment, made)
    diag = mi.diagnose(_lab(run("r1", 0.3, 1), run("r2", 0.6, 2), masses=False))
    assert diag._repr_html_() in diagnosis_html_page(diag, made, "sim")
    from momentid.estimation.scaled import amplitude_trend, identify_per_run

    trend = amplitude_trend(identify_per_run(experiment))
    assert "Mode 1 over 3 runs" in trend._repr_html_() and ESCAPED in trend._repr_html_()


def test_refused_damping_is_said_on_the_page():
    """A damping ratio that is not an answer is marked as such in the table and the headline."""
    from momentid.estimation.summary_html import modal_html

    experiment = _lab(run("r1", 0.3, 1), run("r2", 0.6, 2))
    result = mi.identify(experiment)
    flagged = type(result)(**{**result.__dict__, "damping_is_answer": np.array([True, False, True]),
                              "warnings": ("mode 2 at 11 Hz: damping ratio 0.4 % is NOT AN ANSWER: because",)})
    block = modal_html(flagged)
    assert "the damping ratio of mode 2 is <strong class=\"refused\">NOT AN ANSWER</strong>" in block
    assert block.count('<strong class="refused">NOT AN ANSWER</strong>') == 3   # headline, table, warning
    assert '<li class="warning"><strong>WARNING</strong>' in block


def test_added_mass_identification_page(simulated, tmp_path):
    """The default scenario (three runs, two with added mass): M, C, K against the analytic model, the
    UFF modes mass-normalised."""
    rec = tmp_path / "default.mcap"
    write_experiment(rec, simulated("default"))
    assert main(["identify", str(rec), "-o", str(tmp_path / "id")]) == 0
    page = (tmp_path / "id" / "report.html").read_text(encoding="utf-8")
    assert "Against the recording&#x27;s analytic model" in page and "K (N/m, ± one standard error)" in page
    _opens_cleanly(tmp_path / "id" / "report.html")
    result = mi.identify(mi.read_recording(rec))
    modes = [s for s in pyuff.UFF(str(tmp_path / "id" / "modes.uff")).read_sets() if s["type"] == 55]
    shapes = result.modes().shapes
    for i, m in enumerate(modes):
        assert m["modal_m"] == 1.0                                       # phi^T M phi = 1
        # E13.5: six significant digits of each entry, and the largest sets the absolute scale
        assert np.allclose(m["r1"], shapes[:, i], rtol=5e-6, atol=5e-6 * np.max(np.abs(shapes[:, i])))


@pytest.mark.slow
@pytest.mark.parametrize("rig", ["flexible_3storey", "stiff_1storey"])
def test_shipped_rigs_reports_open_in_chromium(rig, tmp_path, capsys):
    rec = tmp_path / f"{rig}.mcap"
    assert main(["import", str(DATA / "mini_shake_table" / rig), "-o", str(rec)]) == 0
    assert main(["identify", str(rec), "-o", str(tmp_path / "id")]) == 0
    assert main(["identify", str(rec), "--per-run", "-o", str(tmp_path / "per_run")]) == 0
    assert main(["twin", str(rec), "-o", str(tmp_path / "twin")]) == 0
    assert main(["diagnose", str(rec), "-o", str(tmp_path / "diag")]) == 0      # every trial of the rig
    folders = ["id", "per_run", "twin", "diag"]
    capsys.readouterr()
    for folder in folders:
        page = tmp_path / folder / "report.html"
        _opens_cleanly(page)
        assert page.stat().st_size < 2_000_000           # docs/reports.md gives the measured sizes


@pytest.mark.slow
def test_simulated_diagnosis_report_opens_in_chromium(tmp_path, capsys):
    """A rig identified with added mass (the hidden extra damper at storey 3): the localisation figure too."""
    assert main(["run", str(Path(__file__).parents[1] / "scenarios" / "hidden" / "damper_storey3.toml"), "-o",
                 str(tmp_path), "-q"]) == 0
    assert main(["diagnose", str(tmp_path / "damper_storey3.mcap"), "-o", str(tmp_path / "diag")]) == 0
    capsys.readouterr()
    load = _opens_cleanly(tmp_path / "diag" / "report.html")
    assert len(load.figures) == 4        # overlay, comparison, where the misfit sits, the localisation
    page = (tmp_path / "diag" / "report.html").read_text(encoding="utf-8")
    assert re.search(r"extra damper at storey 3", page)
