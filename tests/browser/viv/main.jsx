// A minimal Viv page for the peer-viewer tests (tests/python/test_peer_viewers.py): it opens one
// OME-Zarr image with Viv's own loader (`loadOmeZarr`, zarrita underneath) and shows one z plane
// in a `PictureInPictureViewer` (the 2D detail view, no overview), with the contrast limits and
// colours of the store's `omero` channels, as vizarr and other Viv apps do.
//
//   index.html?source=URL&z=Z&width=W&height=H&zmap=level|none
//
// `z` defaults to the middle plane. Viv's 2D layers use the level-0 selection on every pyramid
// level (hms-dbmi/viv#901, "Support downsampled Z"), so a pyramid that also halves z, as ours and
// many 3D OME-Zarr writers do, indexes past the end of the coarse levels. `zmap=level` (the
// default) maps z into each level as vizarr does (hms-dbmi/vizarr#71); `zmap=none` leaves Viv
// as it is.
//
// The view is deterministic: the image's centre at the centre of the W x H canvas, zoomed so that
// the image just fits. `window.viv` reports to the test: {status: "loading" | "loaded" |
// "error" (an error stays, even if tiles load afterwards), error (the first one), viewportLoads
// (times every tile in view had loaded), shape, labels, dtype, z, contrastLimits, colors,
// viewState: {target: [x, y, 0], zoom}, width, height}.

import { loadOmeZarr, PictureInPictureViewer } from "@hms-dbmi/viv";
import React from "react";
import { createRoot } from "react-dom/client";

const params = new URLSearchParams(location.search);
const width = Number(params.get("width") ?? 512);
const height = Number(params.get("height") ?? 512);
const state = (window.viv = { status: "loading", error: null, viewportLoads: 0 });

function hexColour(hex) {
  const s = String(hex ?? "FFFFFF").replace(/^#/, "");
  return [0, 2, 4].map((i) => parseInt(s.slice(i, i + 2), 16));
}

async function main() {
  const source = params.get("source");
  if (!source) throw new Error("no ?source= given");
  const { data, metadata } = await loadOmeZarr(source, { type: "multiscales" });
  const base = data[0];
  const labels = base.labels;
  const shape = base.shape;
  const size = (axis) => (labels.includes(axis) ? shape[labels.indexOf(axis)] : 1);
  const channels = metadata.omero?.channels ?? [];
  const nChannels = Math.min(size("c"), 6);
  const z = params.has("z") ? Number(params.get("z")) : Math.floor(size("z") / 2);
  if ((params.get("zmap") ?? "level") === "level" && labels.includes("z")) mapZPerLevel(data);
  const selections = [];
  const contrastLimits = [];
  const colors = [];
  for (let c = 0; c < nChannels; c++) {
    const sel = {};
    if (labels.includes("c")) sel.c = c;
    if (labels.includes("z")) sel.z = z;
    if (labels.includes("t")) sel.t = 0;
    selections.push(sel);
    const w = channels[c]?.window;
    if (!w) throw new Error(`channel ${c} has no omero window`);
    contrastLimits.push([w.start, w.end]);
    colors.push(hexColour(channels[c]?.color));
  }
  const zoom = Math.log2(Math.min(width / size("x"), height / size("y")));
  const viewState = { id: "detail", target: [size("x") / 2, size("y") / 2, 0], zoom };
  Object.assign(state, { shape, labels, dtype: base.dtype, z, contrastLimits, colors, viewState, width, height });
  const onViewportLoad = () => {
    state.viewportLoads += 1;
    if (state.status === "loading") state.status = "loaded";
  };
  const container = document.getElementById("viewer");
  container.style.width = `${width}px`;
  container.style.height = `${height}px`;
  createRoot(container).render(
    <PictureInPictureViewer
      loader={data}
      selections={selections}
      contrastLimits={contrastLimits}
      colors={colors}
      channelsVisible={colors.map(() => true)}
      viewStates={[viewState]}
      height={height}
      width={width}
      overviewOn={false}
      snapScaleBar={false}
      onViewportLoad={onViewportLoad}
      deckProps={{ onError: (e) => fail(e), glOptions: { preserveDrawingBuffer: true } }}
    />,
  );
}

/** Makes each coarser level answer a level-0 z index with its own plane covering it. */
function mapZPerLevel(levels) {
  const zi = levels[0].labels.indexOf("z");
  const nz0 = levels[0].shape[zi];
  for (const source of levels.slice(1)) {
    const nz = source.shape[zi];
    if (nz === nz0) continue;
    const toLevel = (selection) =>
      Array.isArray(selection)
        ? selection.map((v, i) => (i === zi ? Math.min(nz - 1, Math.floor((v * nz) / nz0)) : v))
        : { ...selection, z: Math.min(nz - 1, Math.floor(((selection.z ?? 0) * nz) / nz0)) };
    for (const method of ["getTile", "getRaster"]) {
      const original = source[method].bind(source);
      source[method] = (config) => original({ ...config, selection: toLevel(config.selection) });
    }
  }
}

/** Records the first error (later ones are often its consequences) and logs every one. */
function fail(e) {
  state.status = "error";
  state.error ??= String(e?.message ?? e);
  console.error("viv:", e);
}

window.addEventListener("unhandledrejection", (e) => fail(e.reason));
main().catch(fail);
