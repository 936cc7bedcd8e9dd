// What the stages that decode share (prepended after common.wgsl and the decoder): the first
// decoding failure recorded for the host (in `errors` of decode_bindings.wgsl), and a vertex's
// split cache decoded.

// Records the first operation that failed to decode: its status, then its address.
fn report(status: u32, addr: u32) {
    for (var k = 0u; k < 16u; k++) {
        let r = atomicCompareExchangeWeak(&errors[0], 0u, status);
        if (r.exchanged) {
            atomicStore(&errors[1], addr);
            return;
        }
        if (r.old_value != 0u) {
            return;
        }
    }
}

// Gives a vertex its operation's split cache: criteria and face count, decoded up to there;
// out of core, PENDING where the operation's node is not resident.
fn with_op(s: ptr<function, VState>, fvid: u32) {
    (*s).faces = 0u;
    (*s).crit = vec4<f32>(0.0);
    (*s).flags = 0u;
    if ((*s).addr == NONE) {
        return;
    }
    let o = decode_op((*s).addr, fvid, (*s).v_end, (*s).pc, state_pos(*s), state_nrm(*s), NONE_ADDR, DECODE_TO_FACES);
    if (o.status == DEC_ABSENT) {
        (*s).flags = PENDING;
        return;
    }
    if (o.status != DEC_OK) {
        report(o.status, (*s).addr);
        return;
    }
    (*s).faces = o.faces;
    (*s).crit = bitcast<vec4<f32>>(o.crit_f);
}

