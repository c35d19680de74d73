//! `crease bridge natnet` (issue 19): being built.

/// Options of `crease bridge natnet`.
#[derive(Clone, Debug, clap::Args)]
pub struct NatnetArgs {}

/// Runs `crease bridge natnet`.
pub fn run(_args: &NatnetArgs) -> anyhow::Result<()> {
    anyhow::bail!("crease bridge natnet is not built yet (issue 19)")
}
