//! `crease bridge vmc` (issue 19): being built.

/// Options of `crease bridge vmc`.
#[derive(Clone, Debug, clap::Args)]
pub struct VmcArgs {}

/// Runs `crease bridge vmc`.
pub fn run(_args: &VmcArgs) -> anyhow::Result<()> {
    anyhow::bail!("crease bridge vmc is not built yet (issue 19)")
}
