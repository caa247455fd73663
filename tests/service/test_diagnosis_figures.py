"""The diagnosis report's figures show what the diagnosis found: a residual panel, the located bands and
the coherence threshold (checked on the figures' artists, before they are saved)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from aslm_core.diagnosis import diagnose  # noqa: E402
from aslm_core.diagnosis.locate import coherence  # noqa: E402
from aslm_sim.cases import make_case  # noqa: E402
from aslm_sim.effects.apply import apply_effect  # noqa: E402
from service.report import _merged, write_report  # noqa: E402


@pytest.fixture(scope="module")
def report():
    case = make_case(1, level=2)
    return diagnose(apply_effect(case, "second_motor", seed=1).window)


@pytest.fixture
def figures(report, tmp_path, monkeypatch):
    kept: dict[str, plt.Figure] = {}
    real_savefig = plt.Figure.savefig

    def savefig(fig, path, *a, **kw):
        kept[str(path).rsplit("/", 1)[-1]] = fig
        return real_savefig(fig, path, *a, **kw)

    monkeypatch.setattr(plt.Figure, "savefig", savefig)
    monkeypatch.setattr(plt, "close", lambda fig=None: None)  # keep them for inspection
    md = write_report(report, tmp_path, title="second motor")
    yield kept, md.read_text(), report
    for fig in kept.values():
        plt.close(fig)


def _labels(ax) -> list[str]:
    return [h.get_label() for h in ax.get_legend_handles_labels()[0]]


def test_residual_panel_is_measured_minus_model_with_located_segments(figures):
    kept, md, report = figures
    assert "![residual over time](residual.png)" in md
    fig, s = kept["residual.png"], report.series[0]
    for ax, ch in zip(fig.axes, ("P", "Q"), strict=True):
        before = next(line for line in ax.get_lines() if line.get_label() == "residual before")
        k0 = s["k0"]
        np.testing.assert_allclose(before.get_ydata(), s[ch][k0:] - s[f"{ch}_before"][k0:])
        if report.located.time_segments.get(ch):
            assert "located segment" in _labels(ax)


def test_spectrum_marks_the_located_bands(figures):
    kept, _, report = figures
    assert report.located.channels, "this case must locate a mismatch"
    for ax, ch in zip(kept["spectrum.png"].axes, ("P", "Q"), strict=True):
        spans = [p.get_window_extent(None) for p in ax.patches]  # axvspan rectangles, in display units
        bands = _merged(report.located.bands.get(ch, []))
        assert len(spans) == len(bands) >= 1 and "located band" in _labels(ax)
        to_data = ax.transData.inverted()
        for extent, (lo, hi) in zip(spans, bands, strict=True):
            (x0, _), (x1, _) = to_data.transform([[extent.x0, 0], [extent.x1, 0]])
            assert (x0, x1) == (pytest.approx(lo, rel=1e-6), pytest.approx(hi, rel=1e-6))


def test_coherence_shows_the_locators_threshold(figures):
    kept, _, report = figures
    s = report.series[0]
    k0, ke = s["k0"], s["ke"]
    expected = coherence(s["P"][k0:ke] - s["P_before"][k0:ke], {}, s["fs"])["threshold"]
    ax = kept["coherence.png"].axes[0]
    line = next(line for line in ax.get_lines() if line.get_label().startswith("threshold"))
    assert list(line.get_ydata()) == pytest.approx([expected, expected]) and 0.0 < expected < 1.0
    assert "located band" in _labels(ax)


def test_merged_bands_join_touching_ones():
    assert _merged([[1, 2], [0.05, 0.5], [0.5, 1], [3, 4]]) == [(0.05, 2.0), (3.0, 4.0)]
