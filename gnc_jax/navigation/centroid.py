"""Optical centroiding of the target in a frame (seed 002 §3.1).

The seed's pipeline, every step with static shapes so it can be ``vmap``ped and scanned:

1. threshold T = 2 x the mean grey level of the image's first column (seed 002, threshold eq.);
2. binarise: g(x, y) = f(x, y) where f > T, else 0 (segmentation eq.);
3. connected-component labelling (8-connectivity) by fixed-count label propagation;
4. grey-weighted centroid of the brightest component (largest summed grey above the
   background), x0 = sum(x I) / sum(I) over the component (centroid eq.);
5. sub-pixel correction: the N x N window centred on the rounded component centroid,
   window-weighted centroid of the segmented grey levels, offset
   dx = sum((j - (N+1)/2) I_ij) / sum(I_ij) (1-based j; sub-pixel eq.).

The weights are grey levels minus the background estimate (the first column's mean, the level
the threshold is twice), so a weight is proportional to the light the target sends.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Float, Int, Scalar


class Centroid(NamedTuple):
    xy: Float[Array, "2"]  # (col, row) in ROI pixels, sub-pixel
    valid: Bool[Array, ""]  # a component was found and the window lies inside the ROI
    pixel_xy: Float[Array, "2"]  # component centroid (before the window correction)
    n_components: Int[Array, ""]
    threshold_dn: Scalar


def label_components(mask: Bool[Array, "h w"], iterations: int) -> tuple[Array, Array]:
    """Connected components (8-connectivity) by fixed-count label propagation.

    Every foreground pixel starts with its own flat index as label; each sweep replaces a label
    by the largest label among the pixel's 3 x 3 neighbours (which are in the same component).
    Labels only grow, and after ``iterations`` sweeps each component carries its largest index
    provided ``iterations`` is at least the longest 8-connected geodesic distance from that
    pixel inside the component (a convex blob: its diameter in pixels). A sweep is nine
    shifted maxima (no gathers, which cost ~20 sweeps each under ``vmap`` on CPU).

    Returns:
        labels (int, -1 on background) and ``converged`` (one more sweep changes nothing).
    """
    h, w = mask.shape
    idx = jnp.arange(h * w).reshape(h, w)
    lab0 = jnp.where(mask, idx, -1)

    def sweep(lab):
        p = jnp.pad(lab, 1, constant_values=-1)
        m = lab
        for di in range(3):
            for dj in range(3):
                m = jnp.maximum(m, p[di : di + h, dj : dj + w])
        return jnp.where(mask, m, -1)

    lab = jax.lax.fori_loop(0, iterations, lambda _, x: sweep(x), lab0)
    return lab, jnp.all(sweep(lab) == lab)


def extract_centroid(dn: Float[Array, "h w"], window_px: int, iterations: int) -> Centroid:
    """Seed 002 §3.1 centroid of the brightest target in ``dn`` (grey levels)."""
    h, w = dn.shape
    background = jnp.mean(dn[:, 0])
    threshold = 2.0 * background
    mask = dn > threshold
    weight = jnp.where(mask, dn - background, 0.0)
    labels, _ = label_components(mask, iterations)
    seg = jnp.where(mask, labels, h * w)  # background -> dump segment
    sums = jax.ops.segment_sum(weight.ravel(), seg.ravel(), num_segments=h * w + 1)[:-1]
    best = jnp.argmax(sums)
    comp = mask & (labels == best)
    cw = jnp.where(comp, weight, 0.0)
    total = jnp.sum(cw)
    found = total > 0.0
    safe = jnp.where(found, total, 1.0)
    rows, cols = jnp.meshgrid(jnp.arange(h), jnp.arange(w), indexing="ij")
    x0 = jnp.sum(cw * cols) / safe
    y0 = jnp.sum(cw * rows) / safe

    # Sub-pixel correction in the N x N window centred on the pixel-level centre.
    half = (window_px - 1) // 2
    ci, cj = jnp.round(y0).astype(int), jnp.round(x0).astype(int)
    si, sj = ci - half, cj - half
    inside = (si >= 0) & (sj >= 0) & (si + window_px <= h) & (sj + window_px <= w)
    win = jax.lax.dynamic_slice(weight, (si, sj), (window_px, window_px))
    k = jnp.arange(window_px) - half  # j - (N+1)/2 with 1-based j
    wsum = jnp.sum(win)
    wsafe = jnp.where(wsum > 0.0, wsum, 1.0)
    dx = jnp.sum(win * k[None, :]) / wsafe
    dy = jnp.sum(win * k[:, None]) / wsafe
    xy = jnp.stack([cj + dx, ci + dy]).astype(float)
    n_comp = jnp.sum(mask & (labels == jnp.arange(h * w).reshape(h, w)))
    return Centroid(
        xy=xy,
        valid=found & inside & (wsum > 0.0),
        pixel_xy=jnp.stack([x0, y0]),
        n_components=n_comp,
        threshold_dn=threshold,
    )
