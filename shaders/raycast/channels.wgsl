// The ray caster, part 5 of 7 (joined in order by viewer/src/gpu/contract.rs): sampling
// every channel at its level, with substitution of missing bricks.

// ---- sampling every channel ----

struct ChannelSamples {
    have: u32, // bits: the channels with a value (not clear)
    used: u32, // finest level sampled
    any_value: bool, // some channel had data (a clear sample counts)
}

// Samples every channel not empty here at its chosen level, substituting missing bricks from
// the levels the node maps, into `values` (only where `have` says). For ACTION_REQUEST this
// only requests the bricks.
fn sample_channels(
    ray: Ray,
    v: Visit,
    chosen: ChannelLevels,
    values: ptr<function, array<f32, MAX_CHANNELS>>,
    t: f32,
    skipping: bool,
    substitute: bool,
) -> ChannelSamples {
    var out = ChannelSamples(0u, P.level_count - 1u, false);
    // Only the channels not empty here (take_channel).
    var need = drawn_channels() & ~v.empty;
    loop {
        if need == 0u {
            break;
        }
        let c = take_channel(&need);
        let l = level_of(chosen, c);
        if l == NO_LEVEL {
            continue;
        }
        var k = l;
        var s = Sampled(0.0, false, 0u, false);
        var first_missing = 0u;
        if RESIDENT_ONLY {
            s = sample_filtered(c, l, ray.cell, ray.local, false, t);
        } else {
            var mask = 0u;
            if METHOD == METHOD_RESIDENCY {
                if v.action == ACTION_REQUEST && skipping {
                    let lo = bitcast<f32>(node_word(v.node, c, 1u));
                    let hi = bitcast<f32>(node_word(v.node, c, 2u));
                    if lo == hi {
                        continue; // homogeneous: known without its bricks
                    }
                }
            }
            // Coarse first: where nothing of this channel is resident (ACTION_REQUEST), ask for
            // its coarsest allowed level first. Once that stands in, rays gather opacity and
            // stop early, so the finer bricks behind opaque matter are never requested. Where
            // the coarsest level is clear (averaging can take thin bright structures below the
            // TF), it says nothing of finer ones: then the wanted level is asked for. (One
            // sample_filtered call site: on lavapipe every inlined copy costs every sample.)
            var coarse_first = false;
            if METHOD == METHOD_RESIDENCY && v.action == ACTION_REQUEST && substitute {
                k = min(S.channels[c].max_level, P.level_count - 1u);
                coarse_first = k != l;
            }
            loop {
                s = sample_filtered(c, k, ray.cell, ray.local, k == l || coarse_first, t);
                if coarse_first {
                    coarse_first = false;
                    if !s.clear {
                        s.ok = false; // requested: nothing to sample in ACTION_REQUEST
                        break;
                    }
                    k = l;
                    continue;
                }
                if s.ok {
                    break;
                }
                if k == l {
                    first_missing = s.missing;
                    // The levels the node maps for this channel, read only once a sample misses.
                    if METHOD == METHOD_RESIDENCY && substitute && v.action == ACTION_SAMPLE {
                        mask = node_word(v.node, c, 0u);
                    }
                    // The segment methods keep no residency masks: every level may stand in,
                    // coarser first, as its page table says.
                    if (METHOD == METHOD_SPARSELEAP || METHOD == METHOD_RASTERIZE) && substitute {
                        mask = (1u << P.level_count) - 1u;
                    }
                }
                k = next_candidate(mask, l, k);
                if k == NO_LEVEL {
                    break;
                }
            }
        }
        if s.ok {
            if !RESIDENT_ONLY && k != l {
                note_substituted(first_missing - 1u);
            }
            if !s.clear {
                (*values)[c] = s.value;
                out.have |= 1u << c;
            }
            out.used = min(out.used, k);
            out.any_value = true;
        }
    }
    return out;
}

