"""The diagnosis report's figures are laid out by fixed margins (no measuring pass): every label,
tick label, title and exponent must still land inside the image, whatever the magnitudes plotted."""

import numpy as np
import pytest

from sim_core.identification import report


def _outside(fig) -> list[str]:
    """What is drawn beyond the image or over the panel to its left: each panel's tight box (its tick
    labels, axis labels, offset exponent, title and legend, as ``bbox_inches="tight"`` measures them)."""
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    W, H = fig.canvas.get_width_height()
    out = []
    for i, ax in enumerate(fig.axes):
        b = ax.get_tightbbox(r)
        if b.x0 < -0.5 or b.y0 < -0.5 or b.x1 > W + 0.5 or b.y1 > H + 0.5:
            out.append(f"panel {i}: x {b.x0:.0f}-{b.x1:.0f}, y {b.y0:.0f}-{b.y1:.0f} of {W}x{H} px")
        if i and b.x0 < fig.axes[i - 1].bbox.x1:
            out.append(f"panel {i}'s labels reach into panel {i - 1} ({b.x0:.0f} < {fig.axes[i - 1].bbox.x1:.0f} px)")
    return out


@pytest.mark.parametrize("scale", [3e-5, 7.5e-3, 0.3, 12.5, 3.3e3, 4.4e5])
@pytest.mark.parametrize("panels", [1, 2])
def test_every_text_of_a_figure_lies_inside_it(scale, panels):
    plt = report._pyplot()
    t = np.linspace(0.0, 60.0, 3000)
    fig, axes = plt.subplots(1, panels, figsize=(10, 3.0), squeeze=False)
    for ax in axes[0]:
        ax.plot(t, -scale * (0.2 + np.sin(t)), label="measured - baseline")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("angle residual (rad)")
        ax.set_title("velocity residual autocorrelation (99 % band)", fontsize=9)
        ax.legend(fontsize=7)
    report.layout(fig)
    try:
        assert _outside(fig) == []
    finally:
        plt.close(fig)
