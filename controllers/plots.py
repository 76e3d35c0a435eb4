"""Figures of the reproduction (PNG files a person can look at), one function per scenario."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .scenarios import (MARS_ARM_JOINTS, MARS_DEADBAND_V, MARS_SETTLED_RAD,  # noqa: E402
                        feedforward_prediction, reversal_mask)

C_EMU, C_SIM, C_REF, C_ALT = "tab:blue", "tab:orange", "k", "tab:red"


def _shade(ax, t, mask, label=None):
    on = False
    for i in range(len(t)):
        if mask[i] and not on:
            start, on = t[i], True
        if on and (not mask[i] or i == len(t) - 1):
            ax.axvspan(start, t[i], color="0.88", lw=0, label=label)
            label, on = None, False


def _save(fig, path: Path, tight: bool = True) -> Path:
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_stick(spec, runs, metrics, out: Path) -> list[Path]:
    em, si = runs["emulated"], runs["simulated"]
    a = list(em["joints"]).index("stick")
    mode = metrics["run"]["mode"]
    paths = []
    # Fig. 11: desired and actual stick angle
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(em["t"], em["q_d"][:, a], color=C_REF, lw=2.5, label="desired")
    ax.plot(em["t"], em["angle"][:, a], color=C_EMU, lw=1.2, label=f"emulated (CAN, {mode})")
    ax.plot(si["t"], si["angle"][:, a], color=C_SIM, lw=1.0, ls="--", label="simulated (in-process)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("stick angle (rad)")
    ax.set_title("Fig. 11: desired and actual stick angle under joint PID (responses overlapping)")
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    paths.append(_save(fig, out / "fig11_stick_angle.png"))
    # Fig. 12: tracking errors, simulated vs emulated
    e_em = (em["q_d"][:, a] - em["angle"][:, a]) * 1e3
    e_si = (si["q_d"][:, a] - si["angle"][:, a]) * 1e3
    e_si_em = np.interp(em["t"], si["t"], e_si)     # on the emulated run's time grid
    fig, ax = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    ax[0].plot(em["t"], e_em, color=C_EMU, lw=1.0, label=f"emulated (CAN, {mode})")
    ax[0].plot(si["t"], e_si, color=C_SIM, lw=1.0, ls="--", label="simulated (in-process)")
    ax[0].set_ylabel("tracking error (mrad)")
    m = metrics["emulated"]
    ax[0].set_title(f"Fig. 12: stick tracking error, rms {m['rms_error_rad'] * 1e3:.1f} mrad, "
                    f"max {m['max_error_rad'] * 1e3:.1f} mrad (0.5 rad peak-to-peak command)")
    ax[0].legend(loc="best")
    ax[0].grid(alpha=0.3)
    ax[1].plot(em["t"], e_em - e_si_em, color="0.3", lw=0.8)
    d = metrics["emulated_vs_simulated"]
    ax[1].set_ylabel("emulated -\nsimulated (mrad)")
    ax[1].set_xlabel("time (s)")
    ax[1].set_title(f"difference: rms {d['rms_difference_rad'] * 1e3:.2f} mrad (CAN quantisation: 0.1 mrad angles, 1 mV commands)",
                    fontsize=9)
    ax[1].grid(alpha=0.3)
    paths.append(_save(fig, out / "fig12_stick_error.png"))
    # Fig. 14: feedforward prediction vs the PID's voltage command
    u = em["u"][:, a]
    u_ff = feedforward_prediction(spec, em, "stick")
    rev = reversal_mask(em["t"], em["qd_d"][:, a])
    f = metrics["feedforward"]
    fig, ax = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    _shade(ax[0], em["t"], rev, "spool reversal windows")
    ax[0].plot(em["t"], u, color=C_EMU, lw=1.2, label="PID voltage command")
    ax[0].plot(em["t"], u_ff, color=C_ALT, lw=1.0, ls="--", label="feedforward prediction, eqs. (19)-(21)")
    w = spec.effects and [e.params["width"] for e in spec.effects if e.name == "deadband" and e.joint == "stick"]
    if w:
        ax[0].axhspan(-w[0], w[0], color="tab:green", alpha=0.12, lw=0, label=f"valve deadband ±{w[0]:g} V")
    ax[0].set_ylabel("stick valve command (V)")
    ax[0].set_title("Fig. 14: feedforward prediction vs PID voltage command (emulated run)")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[0].grid(alpha=0.3)
    _shade(ax[1], em["t"], rev)
    ax[1].plot(em["t"], u_ff - u, color="0.3", lw=0.8)
    ax[1].set_ylabel("difference (V)")
    ax[1].set_xlabel("time (s)")
    ax[1].set_title(f"rms difference {f['rms_difference_away_from_reversals_v']:.2f} V away from reversals "
                    f"({100 * f['relative_difference_away_from_reversals']:.1f} % of the command), "
                    f"{f['rms_difference_at_reversals_v']:.2f} V around them", fontsize=9)
    ax[1].grid(alpha=0.3)
    paths.append(_save(fig, out / "fig14_feedforward.png"))
    return paths


def plot_cartesian(spec, runs, metrics, out: Path) -> list[Path]:
    em = runs["emulated"]
    mode = metrics["run"]["mode"]
    joints = list(em["joints"])
    fig = plt.figure(figsize=(14, 7.5))
    gs = fig.add_gridspec(3, 3, width_ratios=[1.5, 1, 1], wspace=0.4)
    ax3 = fig.add_subplot(gs[:, 0], projection="3d")
    ax3.plot(*em["p_d"].T, color=C_REF, lw=2.5, label="commanded path")
    ax3.plot(*em["p_m"].T, color=C_EMU, lw=1.2, label=f"response (emulated, {mode})")
    if "pid_only" in runs:
        ax3.plot(*runs["pid_only"]["p_m"].T, color=C_ALT, lw=0.8, ls=":", label="response, PID without feedforward (sim.)")
    ax3.scatter(*em["p_d"][0], color="g", s=30, label="start")
    ax3.scatter(*em["p_d"][-1], color="r", s=30, label="end")
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    m = metrics["emulated"]
    ax3.set_title(f"(a) end-point path, {m['path_length_m']:.2f} m\nrms error {100 * m['rms_error_m']:.1f} cm "
                  f"({100 * m['relative_error']:.2f} % of the path)", fontsize=10)
    ax3.legend(loc="upper left", fontsize=7)
    t = em["t"]
    for k, (lab, letter) in enumerate(zip("xyz", "bcd")):
        ax = fig.add_subplot(gs[k, 1])
        ax.plot(t, 100 * (em["p_d"][:, k] - em["p_m"][:, k]), color=C_EMU, lw=1.0, label="emulated")
        if "simulated" in runs:
            si = runs["simulated"]
            ax.plot(si["t"], 100 * (si["p_d"][:, k] - si["p_m"][:, k]), color=C_SIM, lw=0.9, ls="--", label="simulated")
        if "pid_only" in runs:
            po = runs["pid_only"]
            ax.plot(po["t"], 100 * (po["p_d"][:, k] - po["p_m"][:, k]), color=C_ALT, lw=0.7, ls=":", label="PID only (sim.)")
        ax.set_ylabel(f"({letter}) {lab} error (cm)")
        ax.grid(alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7)
        if k == 2:
            ax.set_xlabel("time (s)")
    for k, (j, letter) in enumerate(zip(("swing", "boom", "stick"), "efg")):
        a = joints.index(j)
        ax = fig.add_subplot(gs[k, 2])
        ax.plot(t, 1e3 * (em["q_d"][:, a] - em["angle"][:, a]), color=C_EMU, lw=1.0, label="emulated")
        if "simulated" in runs:
            si = runs["simulated"]
            ax.plot(si["t"], 1e3 * (si["q_d"][:, a] - si["angle"][:, a]), color=C_SIM, lw=0.9, ls="--", label="simulated")
        ax.set_ylabel(f"({letter}) {j} error (mrad)")
        ax.grid(alpha=0.3)
        if k == 2:
            ax.set_xlabel("time (s)")
    fig.suptitle("Fig. 15: Cartesian end-point control (operator velocity -> path -> IK -> joint PID + valve feedforward)")
    fig.subplots_adjust(left=0.02, right=0.98, top=0.9, bottom=0.08, hspace=0.3)
    return [_save(fig, out / "fig15_cartesian.png", tight=False)]


def plot_mars(spec, runs, metrics, out: Path) -> list[Path]:
    em = runs["emulated"]
    mode = metrics["run"]["mode"]
    joints = list(em["joints"])
    fig, axs = plt.subplots(len(MARS_ARM_JOINTS), 2, figsize=(13, 11), sharex=True)
    for r, jj in enumerate(MARS_ARM_JOINTS):
        ax, axu = axs[r]
        for arm, ls, col in (("left", "-", C_EMU), ("right", "-", "tab:purple")):
            j = f"{arm}_{jj}"
            if j not in joints:
                continue
            a = joints.index(j)
            ax.plot(em["t"], 1e3 * (em["q_d"][:, a] - em["angle"][:, a]), color=col, lw=1.0, ls=ls,
                    label=f"designed PID, {arm} arm (emulated, {mode})")
            axu.plot(em["t"], em["u_applied"][:, a], color=col, lw=0.9, ls=ls, label=f"designed, {arm}")
            if "plain_pid" in runs and arm == "left":
                pp = runs["plain_pid"]
                ax.plot(pp["t"], 1e3 * (pp["q_d"][:, a] - pp["angle"][:, a]), color=C_ALT, lw=0.9,
                        label="plain PID, left arm (simulated)")
                axu.plot(pp["t"], pp["u_applied"][:, a], color=C_ALT, lw=0.8, label="plain PID, left")
        ax.axhspan(-1e3 * MARS_SETTLED_RAD, 1e3 * MARS_SETTLED_RAD, color="tab:green", alpha=0.12, lw=0)
        ax.set_ylim(-35, 35)
        ax.set_ylabel(f"{jj} error (mrad)")
        axu.axhspan(-MARS_DEADBAND_V, MARS_DEADBAND_V, color="tab:green", alpha=0.12, lw=0)
        axu.set_ylim(-5, 5)
        axu.set_ylabel(f"{jj} valve command (V)")
        ax.grid(alpha=0.3)
        axu.grid(alpha=0.3)
        if r == 0:
            ax.legend(fontsize=7, loc="upper right")
            axu.legend(fontsize=7, loc="upper right")
    axs[-1, 0].set_xlabel("time (s)")
    axs[-1, 1].set_xlabel("time (s)")
    m = metrics["emulated"]
    pp = metrics.get("plain_pid")
    title = (f"MARS-ND: joint PID through {len(set(h['target'] for h in m['holds']))} targets (right arm mirrored) with a "
             f"{MARS_DEADBAND_V:g} V valve deadband (shaded right; left: the ±{1e3 * MARS_SETTLED_RAD:g} mrad settled band).\n"
             f"Designed PID: {m['settled_holds']}/{m['n_holds']} holds settled")
    if pp:
        title += f"; plain PID: {pp['settled_holds']}/{pp['n_holds']}"
    fig.suptitle(title, fontsize=11)
    return [_save(fig, out / "mars_nd_targets.png")]


PLOTS = {"stick": plot_stick, "cartesian": plot_cartesian, "mars_nd": plot_mars}
