//! Reading the render service's VDI answers off the page's main thread.
//!
//! The page's `vdi_worker.js` is a module worker that runs this same WebAssembly. It hands
//! each answer's bytes to [`read_vdi_answer`], which decodes the VDI (decompressed, converted,
//! its values checked) and builds the ray caster's [`VdiBuffers`] (slots packed, skipping
//! grids): the CPU's whole share of a new VDI. It answers a message of typed arrays, whose
//! buffers the worker transfers to the main thread without a copy. There, [`take_answer`]
//! takes the buffers back, checked against their header, and the page uploads them: the list
//! starts and skipping grids copied into its own memory (about 1 MB at 640×360, nearly all of
//! it the list starts), the slots (most of a VDI's bytes) written to the GPU straight from the
//! transferred array ([`VdiSlots`] for `Float32Array`). A 7 MB VDI used to hold the main thread
//! (and with it the frames and the page's input) for the whole decode and setup.
//!
//! The message's fields are named here only. The page's JavaScript passes it on whole; the
//! worker reads only its `transfer` list, for `postMessage`.

use residency_schemas::vdi::{VdiHeader, VolumetricDepthImage};
use wasm_bindgen::prelude::*;

use super::fetch::js_text;
use super::now_ms;
use crate::error_chain;
use crate::gpu::vdi_buffers::{VdiBuffers, VdiBuffersError, VdiSlots};

/// The VDI's header, as JSON.
const HEADER: &str = "header";
/// [`VdiBuffers::starts`], a `Uint32Array`.
const STARTS: &str = "starts";
/// [`VdiBuffers::slots`], a `Float32Array` of four values a slot.
const SLOTS: &str = "slots";
/// [`VdiBuffers::tiles`], a `Uint32Array`.
const TILES: &str = "tiles";
/// The reader's time on the answer, ms.
const READ_MS: &str = "read_ms";
/// Why the answer is no VDI: the decoder's message, whole chain.
const ERROR: &str = "error";
/// The typed arrays' buffers, for `postMessage` to transfer.
const TRANSFER: &str = "transfer";

/// Why a reader's message cannot be taken back.
#[derive(Debug, thiserror::Error)]
pub enum ReaderError {
    /// A field is missing or of another type (a reader of another build).
    #[error("its message has no {field} of the right type")]
    Field {
        /// The field.
        field: &'static str,
    },
    /// The header does not parse.
    #[error("its message's header does not parse")]
    Header(#[source] serde_json::Error),
    /// The buffers do not fit the header.
    #[error("its buffers do not fit their VDI")]
    Buffers(#[source] VdiBuffersError),
}

/// An answer as the reader read it, on the main thread.
pub enum ReadAnswer {
    /// A VDI's buffers, and the reader's time on it (ms).
    Vdi {
        /// The buffers, checked against their header; the slots as the reader transferred
        /// them.
        buffers: Box<VdiBuffers<js_sys::Float32Array>>,
        /// The reader's time, off the main thread: decode and buffers built.
        read_ms: f64,
    },
    /// The answer is no VDI: the decoder's message.
    NotVdi(String),
}

/// Reads one answer of the render service (`bytes`, as the service encoded them), in the
/// page's worker. Answers a message for [`take_answer`]: the VDI's header and buffers, with
/// `transfer` listing the typed arrays' buffers; or `error`, the decoder's message.
#[wasm_bindgen]
pub fn read_vdi_answer(bytes: &[u8]) -> js_sys::Object {
    let started = now_ms();
    let message = js_sys::Object::new();
    let set = |field: &str, value: &JsValue| {
        js_sys::Reflect::set(&message, &JsValue::from_str(field), value)
            .expect("setting a field of a fresh object");
    };
    let vdi = match VolumetricDepthImage::decode(bytes, "the render service's answer") {
        Ok(vdi) => vdi,
        Err(e) => {
            set(ERROR, &JsValue::from_str(&error_chain(&e)));
            return message;
        }
    };
    let buffers = VdiBuffers::of(&vdi);
    drop(vdi);
    let header = serde_json::to_string(&buffers.header).expect("VDI headers serialize");
    let starts = js_sys::Uint32Array::from(buffers.starts.as_slice());
    let slots = js_sys::Float32Array::from(bytemuck::cast_slice::<[f32; 4], f32>(&buffers.slots));
    let tiles = js_sys::Uint32Array::from(buffers.tiles.as_slice());
    let transfer = js_sys::Array::of3(&starts.buffer(), &slots.buffer(), &tiles.buffer());
    set(HEADER, &JsValue::from_str(&header));
    set(STARTS, &starts);
    set(SLOTS, &slots);
    set(TILES, &tiles);
    set(TRANSFER, &transfer);
    set(READ_MS, &JsValue::from_f64(now_ms() - started));
    message
}

/// The reader's message for one answer ([`read_vdi_answer`]), taken back on the main thread:
/// the list starts and skipping grids copied into this side's memory, the slots kept as the
/// transferred array, the buffers checked against their header.
///
/// # Errors
/// A [`ReaderError`] for a message [`read_vdi_answer`] would not write.
pub fn take_answer(message: &JsValue) -> Result<ReadAnswer, ReaderError> {
    let field = |field: &'static str| {
        js_sys::Reflect::get(message, &JsValue::from_str(field))
            .ok()
            .filter(|v| !v.is_undefined())
    };
    let missing = |field| ReaderError::Field { field };
    if let Some(error) = field(ERROR) {
        return error
            .as_string()
            .map(ReadAnswer::NotVdi)
            .ok_or(missing(ERROR));
    }
    let header = field(HEADER)
        .and_then(|h| h.as_string())
        .ok_or(missing(HEADER))?;
    let header: VdiHeader = serde_json::from_str(&header).map_err(ReaderError::Header)?;
    let u32s = |name| {
        field(name)
            .and_then(|v| v.dyn_into::<js_sys::Uint32Array>().ok())
            .map(|a| a.to_vec())
            .ok_or(missing(name))
    };
    let starts = u32s(STARTS)?;
    let tiles = u32s(TILES)?;
    let slots = field(SLOTS)
        .and_then(|v| v.dyn_into::<js_sys::Float32Array>().ok())
        .filter(|a| a.length() % 4 == 0)
        .ok_or(missing(SLOTS))?;
    let read_ms = field(READ_MS)
        .and_then(|v| v.as_f64())
        .ok_or(missing(READ_MS))?;
    let buffers =
        VdiBuffers::from_parts(header, starts, slots, tiles).map_err(ReaderError::Buffers)?;
    Ok(ReadAnswer::Vdi {
        buffers: Box::new(buffers),
        read_ms,
    })
}

/// The slots as the page's VDI reader transferred them, four values a slot: written to the
/// GPU straight from the array (WebGPU's `writeBuffer` with the array as its source), never
/// copied into WebAssembly memory. On another backend (none the page uses today) they are
/// copied in and written as wgpu writes a slice.
impl VdiSlots for js_sys::Float32Array {
    fn count(&self) -> u64 {
        u64::from(self.length() / 4)
    }

    fn write_to(&self, queue: &wgpu::Queue, buffer: &wgpu::Buffer) -> Result<(), String> {
        if let (Some(queue), Some(buffer)) = (queue.as_webgpu(), buffer.as_webgpu()) {
            return queue
                .write_buffer_with_u32_and_buffer_source(buffer, 0, self)
                .map_err(|e| js_text(&e));
        }
        queue.write_buffer(buffer, 0, bytemuck::cast_slice(&self.to_vec()));
        Ok(())
    }
}
