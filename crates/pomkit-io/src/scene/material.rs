//! Loading a `[[material]]`: the parameters (checked against the parameter table's ranges) and
//! the textures it names, files or built-in maps.

use super::*;

impl Loader<'_> {
    pub(super) fn material(&mut self, i: usize, m: &MaterialFile) -> Result<Material, SceneError> {
        let name = m.name.clone().unwrap_or_else(|| format!("material {}", i + 1));
        let at = match (&m.from_object, &m.name) {
            (Some(object), _) => object.clone(),
            (None, Some(n)) => format!("material {n:?}"),
            (None, None) => format!("material {}", i + 1),
        };
        let at = at.as_str();
        // A texture-library folder's maps, filled in as if the table named them.
        let filled;
        let m = if m.folder.is_some() {
            filled = self.folder_material(at, m)?;
            &filled
        } else {
            m
        };
        let d = Material::default();
        let td = TraceParams::default();

        let technique = match &m.technique {
            Some(t) => t.parse::<Technique>().map_err(|_| {
                let names: Vec<&str> = Technique::ALL.iter().map(|t| t.name()).collect();
                self.invalid(
                    at,
                    "technique",
                    format!("technique {t:?} is unknown: expected one of {}", names.join(", ")),
                )
            })?,
            None => d.technique,
        };
        let edges = match m.edges.as_deref() {
            None => d.edges,
            Some(e) => EdgeMode::from_name(e).ok_or_else(|| {
                self.invalid(at, "edges", format!("edges {e:?} is unknown: expected {}", params::EDGES.kind.describe()))
            })?,
        };
        let shadow_mode = match &m.shadow {
            Some(s) => s.parse::<ShadowMode>().map_err(|_| {
                let names: Vec<&str> = ShadowMode::ALL.iter().map(|m| m.name()).collect();
                self.invalid(at, "shadow", format!("shadow {s:?} is unknown: expected one of {}", names.join(", ")))
            })?,
            None => d.shadow.mode,
        };
        let channel = match &m.channel {
            Some(c) => c.parse::<Channel>().map_err(|_| {
                let names: Vec<&str> = Channel::ALL.iter().map(|c| c.name()).collect();
                self.invalid(at, "channel", format!("channel {c:?} is unknown: expected one of {}", names.join(", ")))
            })?,
            None => Channel::Luma,
        };

        let depth_scale = m.depth_scale.unwrap_or(d.depth_scale);
        let trace = TraceParams {
            min_samples: m.min_samples.unwrap_or(td.min_samples),
            max_samples: m.max_samples.unwrap_or(td.max_samples),
            samples: m.samples.unwrap_or(td.samples),
            iterations: m.iterations.unwrap_or(td.iterations),
            binary_steps: m.binary_steps.unwrap_or(td.binary_steps),
            refine: m.refine.unwrap_or(td.refine),
            perspective_bias: m.perspective_bias.unwrap_or(td.perspective_bias),
            lod: td.lod,
        };
        pomkit_core::trace::check_depth_scale(depth_scale).and_then(|()| trace.validate()).map_err(|e| {
            let field = match e {
                TraceParamError::DepthScale(_) => "depth_scale",
                TraceParamError::PerspectiveBias(_) => "perspective_bias",
                TraceParamError::SampleBounds { .. } => "min_samples",
                _ => "trace parameters",
            };
            self.invalid(at, field, e.to_string())
        })?;
        let mut shadow = d.shadow;
        shadow.mode = shadow_mode;
        shadow.softness = self.param(at, &params::SOFTNESS, m.softness.unwrap_or(d.shadow.softness))?;
        let lod_threshold = self.param(at, &params::LOD_THRESHOLD, m.lod_threshold.unwrap_or(d.lod_threshold))?;
        let specular = self.param(at, &params::SPECULAR, m.specular.unwrap_or(d.specular))?;
        let shininess = self.param(at, &params::SHININESS, m.shininess.unwrap_or(d.shininess))?;
        let base_color = match m.base_color {
            Some(c) => self.color(at, "base_color", c)?,
            None => d.base_color,
        };

        // Textures.
        let height = match &m.height {
            Some(h) => {
                let source = self.source(at, "height", h)?;
                let opts = HeightLoadOptions {
                    depth_map: m.depth_map.unwrap_or(false),
                    channel,
                    normalize: m.normalize.unwrap_or(false),
                };
                if matches!(source, Source::Builtin(..)) {
                    let set = [
                        ("depth_map", opts.depth_map),
                        ("channel", opts.channel != Channel::Luma),
                        ("normalize", opts.normalize),
                    ];
                    if let Some((field, _)) = set.into_iter().find(|(_, on)| *on) {
                        return Err(self.invalid(
                            at,
                            field,
                            format!("{field} describes how to read a height image: it does not apply to {h:?}"),
                        ));
                    }
                }
                Some(self.height(at, source, opts)?)
            }
            None => {
                let set = [
                    ("depth_map", m.depth_map.is_some()),
                    ("channel", m.channel.is_some()),
                    ("normalize", m.normalize.is_some()),
                ];
                if let Some((field, _)) = set.into_iter().find(|(_, on)| *on) {
                    return Err(self.invalid(at, field, format!("{field} is set but the material has no height map")));
                }
                // What only a relief can do: cut the silhouette, shade by its depth.
                if m.silhouette == Some(true) {
                    return Err(self.invalid(
                        at,
                        "silhouette",
                        "silhouette = true cuts the outline along the relief, but the material has no height map",
                    ));
                }
                if m.shadow.is_some() && shadow_mode == ShadowMode::Depth {
                    return Err(self.invalid(
                        at,
                        "shadow",
                        "shadow = \"depth\" shades by the depth of the relief, but the material has no height map",
                    ));
                }
                if let Some(t) = m.technique.as_ref().filter(|_| technique.displaces()) {
                    return Err(self.invalid(
                        at,
                        "technique",
                        format!(
                            "technique {t:?} displaces by a height map, but the material has none: add height = ..."
                        ),
                    ));
                }
                None
            }
        };
        let albedo = match &m.albedo {
            Some(a) => {
                let source = self.source(at, "albedo", a)?;
                Some(self.albedo(at, source)?)
            }
            None => None,
        };
        let normal_map = match &m.normal {
            Some(n) => {
                let y_down = m.normal_y_down.unwrap_or(false);
                match self.source(at, "normal", n)? {
                    Source::File(path) => {
                        let key = (path, y_down);
                        if let Some(n) = self.cache.normals.get(&key) {
                            Some(n.clone())
                        } else {
                            let map =
                                Arc::new(load_normal_map(&key.0, y_down).map_err(|source| SceneError::Texture {
                                    file: self.file.to_owned(),
                                    at: at.to_owned(),
                                    field: "normal".to_owned(),
                                    cause: Box::new(source),
                                })?);
                            self.cache.normals.insert(key, map.clone());
                            Some(map)
                        }
                    }
                    Source::Builtin(..) => {
                        return Err(self.invalid(
                            at,
                            "normal",
                            format!("normal {n:?}: there are no built-in normal maps; leave normal out to bake one from height"),
                        ));
                    }
                }
            }
            None => {
                if m.normal_y_down.is_some() {
                    return Err(self.invalid(
                        at,
                        "normal_y_down",
                        "normal_y_down is set but the material has no normal map",
                    ));
                }
                None
            }
        };

        let cones = match (&m.cone_map, &height) {
            (None, _) => None,
            (Some(_), None) => {
                return Err(self.invalid(
                    at,
                    "cone_map",
                    "cone_map is set but the material has no height map: the cones belong to one",
                ));
            }
            (Some(c), Some(field)) => match self.source(at, "cone_map", c)? {
                Source::File(path) => {
                    let map = crate::load_cone_map(&path, field.width(), field.height(), edges).map_err(|source| {
                        SceneError::Texture {
                            file: self.file.to_owned(),
                            at: at.to_owned(),
                            field: "cone_map".to_owned(),
                            cause: Box::new(source),
                        }
                    })?;
                    Some(Arc::new(map))
                }
                Source::Builtin(..) => {
                    return Err(self.invalid(
                        at,
                        "cone_map",
                        format!("cone_map {c:?}: there are no built-in cone maps; leave cone_map out to build the cones from height"),
                    ));
                }
            },
        };

        Ok(Material {
            name,
            albedo,
            base_color,
            normal_map,
            height,
            technique,
            depth_scale,
            edges,
            trace,
            shadow,
            lod_threshold,
            specular,
            shininess,
            pixel_depth_offset: m.pixel_depth_offset.unwrap_or(d.pixel_depth_offset),
            silhouette: m.silhouette.unwrap_or(d.silhouette),
            cones,
        })
    }

    /// Parses a texture reference: a path (relative to the scene) or `builtin:NAME[:WxH]`.
    fn source(&self, at: &str, field: &str, value: &str) -> Result<Source, SceneError> {
        if value.trim().is_empty() {
            return Err(self.invalid(at, field, format!("{field} is empty: expected a file name or builtin:NAME")));
        }
        if value.contains('\0') {
            return Err(self.invalid(
                at,
                field,
                format!("{field} {value:?}: a file name cannot contain a NUL byte (\\u{{0}})"),
            ));
        }
        let Some(rest) = value.strip_prefix("builtin:") else {
            return Ok(Source::File(self.base.join(value)));
        };
        let (name, size) = match rest.split_once(':') {
            Some((n, s)) => (n, Some(s)),
            None => (rest, None),
        };
        let pattern = name.parse::<Pattern>().map_err(|_| {
            let names: Vec<&str> = Pattern::ALL.iter().map(|p| p.name()).collect();
            self.invalid(
                at,
                field,
                format!("{field} {value:?}: unknown built-in {name:?}: expected one of {}", names.join(", ")),
            )
        })?;
        let (w, h) = match size {
            None => (BUILTIN_SIZE, BUILTIN_SIZE),
            Some(s) => {
                let parsed = s
                    .split_once(['x', 'X'])
                    .and_then(|(w, h)| Some((w.trim().parse::<u32>().ok()?, h.trim().parse::<u32>().ok()?)));
                match parsed {
                    Some((w, h)) if (1..=MAX_BUILTIN_SIZE).contains(&w) && (1..=MAX_BUILTIN_SIZE).contains(&h) => {
                        (w, h)
                    }
                    _ => {
                        return Err(self.invalid(
                            at,
                            field,
                            format!(
                                "{field} {value:?}: size {s:?} must be WxH with each side from 1 to {MAX_BUILTIN_SIZE}"
                            ),
                        ));
                    }
                }
            }
        };
        Ok(Source::Builtin(pattern, w, h))
    }

    fn height(&mut self, at: &str, source: Source, opts: HeightLoadOptions) -> Result<Arc<HeightField>, SceneError> {
        let key = (source, opts.depth_map, opts.channel, opts.normalize);
        if let Some(f) = self.cache.heights.get(&key) {
            return Ok(f.clone());
        }
        let field = match &key.0 {
            Source::Builtin(p, w, h) => procedural::generate(*p, *w, *h),
            Source::File(path) => load_height_field(path, &opts).map_err(|source| SceneError::Texture {
                file: self.file.to_owned(),
                at: at.to_owned(),
                field: "height".to_owned(),
                cause: Box::new(source),
            })?,
        };
        let field = Arc::new(field);
        self.cache.heights.insert(key, field.clone());
        Ok(field)
    }

    fn albedo(&mut self, at: &str, source: Source) -> Result<Arc<Texture>, SceneError> {
        if let Some(t) = self.cache.albedos.get(&source) {
            return Ok(t.clone());
        }
        let texture = match &source {
            Source::Builtin(p, w, h) => {
                let px = procedural::albedo(*p, *w, *h);
                Texture::from_srgb8(*w, *h, &px)
                    .ok_or_else(|| self.invalid(at, "albedo", "the built-in colour map has the wrong size"))?
            }
            Source::File(path) => load_color_texture(path).map_err(|source| SceneError::Texture {
                file: self.file.to_owned(),
                at: at.to_owned(),
                field: "albedo".to_owned(),
                cause: Box::new(source),
            })?,
        };
        let texture = Arc::new(texture);
        self.cache.albedos.insert(source, texture.clone());
        Ok(texture)
    }
}
