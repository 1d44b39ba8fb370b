//! `lidarsim check`: the report of [`crate::pipeline::check`], a line each.

use super::require_file;
use crate::error::Result;

pub(super) fn check(path: &std::path::Path) -> Result<()> {
    require_file(path)?;
    let report = crate::pipeline::check::check(path)?;
    crate::progress::say(
        &report
            .lines()
            .iter()
            .map(|l| format!("{l}\n"))
            .collect::<String>(),
    )
}
