//! Properties of the flow: time reversal, rest, the LDDMM limit.
