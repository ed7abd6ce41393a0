"""Runs one peer OME-Zarr writer on a u16 TIFF stack, with the settings `ingest` uses:
64³ chunks, blosc-lz4 (clevel 5, byte shuffle), mean downsampling by 2 in every axis, and the
given number of levels. Usage: peers.py TOOL INPUT.tif OUTPUT LEVELS

TOOL is one of: tensorstore, ngff-zarr, ome-zarr, zarr-array (writes the input as a plain
Zarr v3 array, the input zarrs_ome needs)."""

import sys

import numpy as np
import tifffile
import zarr
from zarr.codecs import BloscCodec

CHUNK = 64
BLOSC = {"cname": "lz4", "clevel": 5, "shuffle": "shuffle", "typesize": 2, "blocksize": 0}


def tensorstore_writer(data, out, levels):
    import tensorstore as ts

    def create(path, shape):
        return ts.open(
            {
                "driver": "zarr3",
                "kvstore": {"driver": "file", "path": f"{out}/{path}"},
                "metadata": {
                    "shape": list(shape),
                    "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": [CHUNK] * 3}},
                    "data_type": "uint16",
                    "codecs": [{"name": "bytes", "configuration": {"endian": "little"}}, {"name": "blosc", "configuration": BLOSC}],
                },
                "create": True,
                "delete_existing": True,
            }
        ).result()

    prev = create("0", data.shape)
    prev.write(data).result()
    for level in range(1, levels):
        view = ts.downsample(prev, [2, 2, 2], "mean")
        dst = create(str(level), view.shape)
        dst.write(view).result()
        prev = dst


def ngff_zarr_writer(data, out, levels):
    import ngff_zarr as nz

    image = nz.to_ngff_image(data, dims=["z", "y", "x"])
    ms = nz.to_multiscales(image, scale_factors=[2**i for i in range(1, levels)], method=nz.Methods.DASK_BIN_SHRINK, chunks=CHUNK)
    nz.to_ngff_zarr(out, ms, version="0.5", compressors=[BloscCodec(cname="lz4", clevel=5, shuffle="shuffle")])


def ome_zarr_writer(data, out, levels):
    from ome_zarr.scale import Methods
    from ome_zarr.writer import write_image

    root = zarr.open_group(out, mode="w", zarr_format=3)
    write_image(
        data,
        root,
        scale_factors=[2**i for i in range(1, levels)],
        method=Methods.LOCAL_MEAN,
        axes="zyx",
        storage_options={"chunks": (CHUNK,) * 3, "compressors": [BloscCodec(cname="lz4", clevel=5, shuffle="shuffle")]},
    )


def zarr_array_writer(data, out, levels):
    arr = zarr.create_array(out, shape=data.shape, chunks=(CHUNK,) * 3, dtype=data.dtype, compressors=[BloscCodec(cname="lz4", clevel=5, shuffle="shuffle")], overwrite=True)
    arr[...] = data


TOOLS = {
    "tensorstore": tensorstore_writer,
    "ngff-zarr": ngff_zarr_writer,
    "ome-zarr": ome_zarr_writer,
    "zarr-array": zarr_array_writer,
}

if __name__ == "__main__":
    tool, src, out, levels = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
    data = tifffile.imread(src)
    assert data.dtype == np.uint16 and data.ndim == 3, (data.dtype, data.shape)
    TOOLS[tool](data, out, levels)
