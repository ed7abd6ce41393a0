//! The brick batch query parser (`brickserver/src/bricks.rs`, `parse_batch`) on any query
//! string and brick cap. An accepted batch holds 1 to `max_bricks` bricks and parses back to
//! itself when written out canonically.
#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use residency_brickserver::bricks::{BatchLimits, parse_batch};
use residency_schemas::wire::BrickEncoding;

#[derive(Arbitrary, Debug)]
struct Input<'a> {
    max_bricks: u16,
    query: &'a str,
}

fuzz_target!(|input: Input<'_>| {
    let limits = BatchLimits {
        max_bricks: input.max_bricks as usize,
        ..BatchLimits::default()
    };
    match parse_batch(input.query, &limits) {
        Ok((bricks, encoding)) => {
            assert!(!bricks.is_empty() && bricks.len() <= limits.max_bricks);
            let list: Vec<String> = bricks
                .iter()
                .map(|b| {
                    let [z, y, x] = b.brick;
                    format!("{},{},{z},{y},{x}", b.level, b.channel)
                })
                .collect();
            let name = match encoding {
                BrickEncoding::Stored => "stored",
                BrickEncoding::Raw => "raw",
            };
            let canonical = format!("encoding={name}&b={}", list.join("%3B"));
            assert_eq!(
                parse_batch(&canonical, &limits),
                Ok((bricks, encoding)),
                "{canonical}"
            );
        }
        Err(e) => assert!(!e.to_string().is_empty()),
    }
});
