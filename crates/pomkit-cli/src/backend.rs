//! `--backend cpu|gpu|auto`, shared by `render` and `bench`: which renderer draws the frames.

use anyhow::{Context, Result};
use clap::ValueEnum;
use pomkit_gpu::{GpuContext, GpuRenderer};

/// The renderer asked for on the command line.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// The CPU renderer (pomkit-cpu), on all cores.
    Cpu,
    /// The wgpu renderer (pomkit-gpu); fails when the machine has no GPU adapter.
    Gpu,
    /// The GPU when an adapter exists, else the CPU; says which on standard error.
    Auto,
}

/// The GPU renderer, or why there is none.
pub enum Opened {
    /// `--backend cpu`: the GPU was not asked for.
    CpuAskedFor,
    /// `--backend auto` found no usable adapter: the reason (it names the fix).
    NoGpu(String),
    /// A renderer on the adapter `ctx.describe()` names.
    Gpu(Box<GpuRenderer>),
}

/// Opens the renderer `backend` asks for and reports the choice on standard error
/// (`backend: gpu (ADAPTER)` or, for `auto` without an adapter, `backend: cpu (REASON)`).
///
/// # Errors
/// `--backend gpu` without a usable adapter: the message names the problem and the fix.
pub fn open(backend: Backend) -> Result<Opened> {
    let ctx = match backend {
        Backend::Cpu => return Ok(Opened::CpuAskedFor),
        Backend::Gpu => GpuContext::new().context("--backend gpu (--backend cpu renders on the CPU instead)")?,
        Backend::Auto => match GpuContext::new() {
            Ok(ctx) => ctx,
            Err(e) => {
                eprintln!("backend: cpu ({e})");
                return Ok(Opened::NoGpu(e.to_string()));
            }
        },
    };
    eprintln!("backend: gpu ({})", ctx.describe());
    Ok(Opened::Gpu(Box::new(GpuRenderer::new(ctx))))
}
