use camsim::{Error, Result};
use clap::Args;

#[derive(Args)]
pub struct DiffArgs {
    /// Results directory or git revision.
    pub a: String,
    /// Results directory or git revision.
    pub b: String,
}

pub fn diff(_a: DiffArgs) -> Result<i32> {
    Err(Error::NotSupported("diff".into()))
}
