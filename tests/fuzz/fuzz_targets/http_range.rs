//! The `Range` header parser (`brickserver/src/responses.rs`, `parse_range`) on any header
//! value and file length. A part it grants lies inside the file and is not empty.
#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use residency_brickserver::responses::{RangeRequest, parse_range};

#[derive(Arbitrary, Debug)]
struct Input<'a> {
    len: u64,
    value: &'a str,
}

fuzz_target!(|input: Input<'_>| {
    match parse_range(input.value, input.len) {
        RangeRequest::Part(start, end) => {
            assert!(start < end && end <= input.len, "{input:?}: {start}..{end}");
        }
        RangeRequest::Whole | RangeRequest::Unsatisfiable => {}
    }
});
