// The page's VDI reader: a module worker that reads the render service's answers off the
// page's main thread, so that frames keep coming while a VDI is read. It runs the viewer's own
// WebAssembly (viewer/src/web/vdi_reader.rs): each answer's bytes are decoded and turned into
// the ray caster's buffers there, and the buffers come back to the page transferred, not
// copied.
//
// Messages in: {sequence, bytes (an ArrayBuffer, transferred)}. Messages out, one each, in
// order: {sequence, read} (read_vdi_answer's message: the buffers, or the decoder's error), or
// {sequence, failed} where the reader itself failed: its WebAssembly did not start, or it
// trapped (a panic, out of memory), after which this worker is spent and the page makes a new
// one.

import init, { read_vdi_answer } from "./residency_viewer.js";

const ready = init();
/** How the page names this worker in its messages. */
const READER = "the page's VDI reader (vdi_worker.js)";

onmessage = async ({ data: { sequence, bytes } }) => {
  try {
    await ready;
  } catch (e) {
    postMessage({ sequence, failed: `${READER} could not start its WebAssembly: ${e}` });
    return;
  }
  let read;
  try {
    read = read_vdi_answer(new Uint8Array(bytes));
  } catch (e) {
    postMessage({ sequence, failed: `${READER} failed: ${e}`, spent: true });
    return;
  }
  postMessage({ sequence, read }, read.transfer ?? []);
};
