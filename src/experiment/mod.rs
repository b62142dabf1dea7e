//! The experiment language (KDL) → typed spec → sweep expansion → run plan,
//! and the runner that drives every stage and writes results.
