//! `lidarsim check`: the report of [`crate::pipeline::check`], a line each.

use super::require_file;
use crate::error::Result;

pub(super) fn check(path: &std::path::Path) -> Result<()> {
    require_file(path)?;
    for line in crate::pipeline::check::check(path)?.lines() {
        println!("{line}");
    }
    Ok(())
}
