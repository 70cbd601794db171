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
