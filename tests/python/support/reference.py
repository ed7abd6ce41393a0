"""The NumPy brute-force reference: the exact pyramid, the region metadata (min/max grids and
histograms) and the histogram bins a value falls in."""

import pathlib

import numpy as np
import zarr

from support.stores import level_factors, root_attributes


def window_sums(a: np.ndarray, f, axis: int) -> np.ndarray:
    """Sums of consecutive windows of `f` along `axis` (a partial last window sums what exists)."""
    return np.add.reduceat(a, np.arange(0, a.shape[axis], f), axis=axis)


def reference_level(level0: np.ndarray, factor) -> np.ndarray:
    """Exact mean of the level-0 voxels each voxel covers (NaN excluded), as float64,
    for a (c, z, y, x) array and a (z, y, x) factor."""
    data = level0.astype(np.float64)
    valid = ~np.isnan(data)
    sums = np.where(valid, data, 0.0)
    counts = valid.astype(np.float64)
    for axis, f in zip((1, 2, 3), factor):
        sums = window_sums(sums, f, axis)
        counts = window_sums(counts, f, axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return sums / counts


def round_half_away(x: np.ndarray) -> np.ndarray:
    """Rounds to the nearest integer, halves away from zero."""
    return np.sign(x) * np.floor(np.abs(x) + 0.5)


def assert_pyramid_exact(store: pathlib.Path, level0: np.ndarray):
    """Every level equals the rounded exact mean of the level-0 voxels it covers."""
    g = zarr.open_group(str(store), mode="r")
    factors = level_factors(store)
    for i, f in enumerate(factors):
        got = g[str(i)][...]
        exact = reference_level(level0, f)
        assert got.shape == exact.shape, (i, got.shape, exact.shape)
        if np.issubdtype(got.dtype, np.integer):
            assert np.abs(got.astype(np.float64) - exact).max() <= 0.5, f"level {i}"
            np.testing.assert_array_equal(got, round_half_away(exact).astype(got.dtype), err_msg=f"level {i}")
        else:
            np.testing.assert_allclose(got, exact.astype(np.float32), rtol=1e-6, atol=0, equal_nan=True, err_msg=f"level {i}")


def assert_same_bits(a: np.ndarray, b: np.ndarray):
    """Same shape, same type and the same bytes (NaN payloads included)."""
    assert a.shape == b.shape and a.dtype == b.dtype, (a.shape, a.dtype, b.shape, b.dtype)
    assert a.tobytes() == b.tobytes()


def histogram_edges(written) -> np.ndarray:
    """Bin edges as written (an infinite edge is JSON null: -inf first, +inf elsewhere)."""
    return np.array([(-np.inf if i == 0 else np.inf) if e is None else e for i, e in enumerate(written)], np.float64)


def histogram_bins_of(edges: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The bin of each non-NaN value: bin i counts edges[i] <= v < edges[i+1], and +inf
    counts in the bin whose upper edge is +inf."""
    idx = np.searchsorted(edges, values, side="right") - 1
    top = int(np.searchsorted(edges, np.inf, side="left"))  # first +inf edge
    return np.where(values == np.inf, top - 1, idx)


def assert_region_metadata(store: pathlib.Path):
    """Min/max cells equal the haloed range of their voxels (so they bound every trilinear
    sample inside them), exact cells the range of their own voxels, coarser grids are the min of mins / max of maxes, and each brick's
    histogram counts every non-NaN voxel in the bin its documented edges give."""
    g = zarr.open_group(str(store), mode="r")
    meta = root_attributes(store)["residency"]
    cell, halo, brick = meta["cell_shape"][0], meta["halo"], meta["brick_shape"]
    bins = meta["histogram_bins"]
    assert meta["version"] == "0.2"
    for lvl in meta["levels"]:
        with np.errstate(invalid="ignore"):  # signalling NaNs
            data = g[lvl["image"]][...].astype(np.float64)
        c_count, nz, ny, nx = data.shape
        # "minmax": haloed ranges (conservative for trilinear samples); "range": exact.
        for kind, h in (("minmax", halo), ("range", 0)):
            assert len(lvl[kind]) == len(lvl["minmax"])
            grid0 = g[lvl[kind][0]["path"]][...].astype(np.float64)
            gz, gy, gx = lvl[kind][0]["grid_shape"]
            assert grid0.shape == (c_count, 2, gz, gy, gx)
            for c in range(c_count):
                for k in range(gz):
                    for j in range(gy):
                        for i in range(gx):
                            box = data[
                                c,
                                max(k * cell - h, 0) : (k + 1) * cell + h,
                                max(j * cell - h, 0) : (j + 1) * cell + h,
                                max(i * cell - h, 0) : (i + 1) * cell + h,
                            ]
                            lo, hi = grid0[c, 0, k, j, i], grid0[c, 1, k, j, i]
                            if np.isnan(box).all():
                                assert np.isnan(lo) and np.isnan(hi)
                            else:
                                assert lo == np.nanmin(box) and hi == np.nanmax(box), (kind, lvl["image"], c, k, j, i)
            prev = grid0
            for grid in lvl[kind][1:]:
                cur = g[grid["path"]][...].astype(np.float64)
                for axis in (2, 3, 4):
                    pad = [(0, 0)] * 5
                    if prev.shape[axis] % 2:
                        pad[axis] = (0, 1)
                    prev = np.pad(prev, pad, mode="edge")
                z, y, x = prev.shape[2:]
                blocks = prev.reshape(c_count, 2, z // 2, 2, y // 2, 2, x // 2, 2)
                np.testing.assert_array_equal(cur[:, 0], np.nanmin(blocks[:, 0], axis=(2, 4, 6)))
                np.testing.assert_array_equal(cur[:, 1], np.nanmax(blocks[:, 1], axis=(2, 4, 6)))
                prev = cur
        hist = g[lvl["histogram"]][...]
        for c in range(c_count):
            edges = histogram_edges(meta["channels"][c]["histogram_edges"])
            for bz in range(hist.shape[1]):
                for by in range(hist.shape[2]):
                    for bx in range(hist.shape[3]):
                        vox = data[
                            c,
                            bz * brick[0] : (bz + 1) * brick[0],
                            by * brick[1] : (by + 1) * brick[1],
                            bx * brick[2] : (bx + 1) * brick[2],
                        ].ravel()
                        vox = vox[~np.isnan(vox)]
                        counts = hist[c, bz, by, bx]
                        assert counts.sum() == vox.size
                        want = np.zeros(bins, dtype=np.int64)
                        idx = histogram_bins_of(edges, vox)
                        np.add.at(want, idx, 1)
                        np.testing.assert_array_equal(counts, want)
