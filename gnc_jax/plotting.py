"""Plotting helpers shared by the systems' report figures (matplotlib, Agg backend)."""

import pathlib

import numpy as np


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend (imported on first use: plotting
    is optional for a study)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def saver(plt, out: pathlib.Path, files: list):
    """``save(fig, name)``: write ``out/name`` at 120 dpi, close the figure, record the path."""

    def save(fig, name):
        files.append(out / name)
        fig.savefig(files[-1], dpi=120, bbox_inches="tight")
        plt.close(fig)

    return save


def ellipse_xy(mean, cov, k, n=200):
    """Points of the k-sigma ellipse of a 2-D covariance (seed 000 eq. 17)."""
    vals, vecs = np.linalg.eigh(cov)
    a = np.linspace(0.0, 2.0 * np.pi, n)
    circle = np.stack([np.cos(a), np.sin(a)])
    return mean[:, None] + k * vecs @ (np.sqrt(np.maximum(vals, 0.0))[:, None] * circle)


def envelope_figures(env, out: pathlib.Path) -> list[pathlib.Path]:
    """One PNG per metric of an envelope (:mod:`gnc_jax.operating_envelope`): a heat map over
    two grid axes (a line over one; none beyond two), infeasible and refused cells marked,
    and the system's overlay (:meth:`~gnc_jax.systems.AbstractSystem.envelope_overlay`)."""
    keys = list(env.axes)
    if len(keys) > 2:
        return []
    plt = pyplot()
    files: list[pathlib.Path] = []
    save = saver(plt, out, files)
    system = env.scenario.system
    xs = np.asarray(env.axes[keys[0]], float)
    ys = np.asarray(env.axes[keys[1]], float) if len(keys) == 2 else None
    for metric, label in env.metrics.items():
        fig, ax = plt.subplots(figsize=(7.5, 5.5))
        if ys is None:
            _envelope_line(ax, env, keys[0], xs, metric, label)
        else:
            _envelope_map(fig, ax, env, keys, xs, ys, metric, label)
        system.envelope_overlay(ax, env, keys[0], keys[1] if ys is not None else None)
        ax.set_title(f"{env.scenario.name}: {label}, {env.runs} runs per cell")
        if ax.get_legend_handles_labels()[0]:  # below the axes: no cell hidden under it
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3)
        save(fig, f"envelope_{metric}.png")
    return files


def _value(cell, metric):
    v = cell.get(metric)
    return np.nan if v is None or cell.get("status") != "simulated" else float(v)


def _edges(v):
    if len(v) == 1:
        return np.array([v[0] - 0.5, v[0] + 0.5])
    mid = 0.5 * (v[1:] + v[:-1])
    return np.concatenate([[2 * v[0] - mid[0]], mid, [2 * v[-1] - mid[-1]]])


def _envelope_map(fig, ax, env, keys, xs, ys, metric, label):
    grid = np.full((len(ys), len(xs)), np.nan)
    status = np.full((len(ys), len(xs)), "", dtype=object)
    for c in env.cells:
        i = int(np.argmin(np.abs(ys - c[keys[1]])))
        j = int(np.argmin(np.abs(xs - c[keys[0]])))
        grid[i, j] = _value(c, metric)
        status[i, j] = c.get("status")
    mesh = ax.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(grid), cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=label)
    for i, y in enumerate(ys):
        for j, x in enumerate(xs):
            if status[i, j] == "simulated" and np.isfinite(grid[i, j]):
                light = mesh.norm(grid[i, j]) > 0.6  # viridis is light at its top
                ax.text(
                    x,
                    y,
                    f"{grid[i, j]:.3g}",
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="k" if light else "w",
                )
            elif status[i, j] in ("infeasible", "refused"):
                ax.text(
                    x,
                    y,
                    "×" if status[i, j] == "infeasible" else "R",
                    ha="center",
                    va="center",
                    fontsize=11,
                    color="0.3",
                )
    ax.set_xlabel(keys[0])
    ax.set_ylabel(keys[1])
    ax.plot([], [], "s", color="0.8", label="× infeasible (pre-check), R refused")


def _envelope_line(ax, env, key, xs, metric, label):
    vals = np.array([_value(c, metric) for c in env.cells])
    ax.plot(xs, vals, "o-", label=label)
    bad = np.array([c.get("status") != "simulated" for c in env.cells])
    if bad.any():
        ax.plot(xs[bad], np.zeros(bad.sum()), "x", color="0.3", label="infeasible / refused")
    ax.set_xlabel(key)
    ax.set_ylabel(label)
    ax.grid(alpha=0.3)
