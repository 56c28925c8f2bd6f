//! `pomkit gltf attach`: a height map put into a glTF file's material as
//! `KHR_materials_displacement` (docs/SCENES.md, Attaching a height map).

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::{Args, Subcommand};
use pomkit_io::gltf::{AttachDepth, MaterialChoice, attach};

use crate::HeightRead;

/// `pomkit gltf VERB`.
#[derive(Subcommand, Debug)]
pub enum GltfVerb {
    /// Put a height map into a material of a glTF file as KHR_materials_displacement, so that
    /// `pomkit render OUT.gltf` traces it.
    Attach(AttachArgs),
}

/// `pomkit gltf attach IN --height H (--depth D | --depth-scale S) -o OUT`.
#[derive(Args, Debug)]
pub struct AttachArgs {
    /// The glTF file (.gltf or .glb).
    input: PathBuf,
    /// The material: its name, or its index (a whole number). May be left out when the file
    /// has one material.
    #[arg(long)]
    material: Option<String>,
    /// Height map: an image file, or `builtin:NAME[:WxH]` (as `pomkit trace --height`).
    #[arg(long = "height", value_name = "H")]
    height: String,
    #[command(flatten)]
    read: HeightRead,
    /// The relief's depth in the file's units (displacementGeometryFactor; the offset is
    /// -depth, so the file's displaced surface is the one pomkit draws).
    #[arg(long, value_name = "D", conflicts_with = "depth_scale")]
    depth: Option<f32>,
    /// The relief's depth in UV units (pomkit's depth_scale), converted to the file's units by
    /// the mean length of a UV unit on the material's meshes.
    #[arg(long, value_name = "S")]
    depth_scale: Option<f32>,
    /// The output (.gltf beside which OUTSTEM_height.png is written, or .glb when the input is
    /// one). It may not be the input or a file the input reads; every file appears only when
    /// all are written.
    #[arg(short, long)]
    output: PathBuf,
}

/// Runs `pomkit gltf VERB`.
pub fn run(verb: &GltfVerb) -> Result<()> {
    match verb {
        GltfVerb::Attach(a) => run_attach(a),
    }
}

fn run_attach(a: &AttachArgs) -> Result<()> {
    let depth = match (a.depth, a.depth_scale) {
        (Some(d), None) => {
            if !(d.is_finite() && d > 0.0) {
                bail!("--depth {d}: it must be a finite number greater than 0 (in the file's units)");
            }
            AttachDepth::Units(d)
        }
        (None, Some(s)) => {
            if let Err(e) = pomkit_core::trace::check_depth_scale(s) {
                bail!("--depth-scale {s}: {e}");
            }
            AttachDepth::UvUnits(s)
        }
        _ => bail!("give the relief's depth: --depth D (in the file's units) or --depth-scale S (in UV units)"),
    };
    let material = match &a.material {
        None => MaterialChoice::Only,
        Some(m) => match m.parse::<usize>() {
            Ok(i) => MaterialChoice::Index(i),
            Err(_) => MaterialChoice::Name(m.clone()),
        },
    };
    let inputs: Vec<PathBuf> =
        if a.height.starts_with("builtin:") { Vec::new() } else { vec![PathBuf::from(&a.height)] };
    // `attach` checks the outputs (never the input, a file it reads, or the height file)
    // before it writes anything.
    let field = crate::load_height(Path::new(&a.height), &a.read)?;
    let done = attach(&a.input, &a.output, &material, &field, depth, &inputs)?;
    eprintln!(
        "wrote {} (material {}: KHR_materials_displacement, factor {}, offset {})",
        a.output.display(),
        done.material,
        done.factor,
        -done.factor
    );
    if let Some(p) = &done.image {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}
