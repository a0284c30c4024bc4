// The shader variants, shared by build.rs (which compiles every one) and the
// renderer (which picks one). A variant is a typed value, not a string of
// macro names, and `Shader::all` lists every value the types can hold, so
// a variant the renderer asks for has always been compiled. Like
// shader_constants.rs, this file is included by build.rs: keep it free of
// `use` and of anything that needs the rest of the crate.

/// How a vertex-placing stage displaces vertices with the material's
/// height maps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Placing {
    /// The heightmap alone.
    Plain,
    /// Height-map displacement, weighted by blend maps or (without) by
    /// height bands; sampled in three projections when `triplanar`.
    Displaced { blend_maps: bool, triplanar: bool },
}

impl Placing {
    pub const ALL: [Placing; 5] = [
        Placing::Plain,
        Placing::Displaced {
            blend_maps: false,
            triplanar: false,
        },
        Placing::Displaced {
            blend_maps: true,
            triplanar: false,
        },
        Placing::Displaced {
            blend_maps: false,
            triplanar: true,
        },
        Placing::Displaced {
            blend_maps: true,
            triplanar: true,
        },
    ];

    fn defines(self) -> Vec<&'static str> {
        match self {
            Placing::Plain => Vec::new(),
            Placing::Displaced {
                blend_maps,
                triplanar,
            } => {
                let mut d = vec!["MATERIAL", "DISPLACE"];
                if blend_maps {
                    d.push("BLEND_MAPS");
                }
                if triplanar {
                    d.push("TRIPLANAR");
                }
                d
            }
        }
    }
}

/// What the fragment shader samples besides the heightmap.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Shading {
    /// Height colours; a lightmap when `lightmap`.
    Heights { lightmap: bool },
    /// Material layers, with their normal maps, blend maps, a lightmap
    /// and triplanar projection as given.
    Material {
        normal_maps: bool,
        blend_maps: bool,
        lightmap: bool,
        triplanar: bool,
    },
}

impl Shading {
    fn all() -> Vec<Shading> {
        let mut all = vec![
            Shading::Heights { lightmap: false },
            Shading::Heights { lightmap: true },
        ];
        for bits in 0..16u32 {
            all.push(Shading::Material {
                normal_maps: bits & 1 != 0,
                blend_maps: bits & 2 != 0,
                lightmap: bits & 4 != 0,
                triplanar: bits & 8 != 0,
            });
        }
        all
    }

    fn defines(self) -> Vec<&'static str> {
        match self {
            Shading::Heights { lightmap } => {
                if lightmap {
                    vec!["LIGHTMAP"]
                } else {
                    vec![]
                }
            }
            Shading::Material {
                normal_maps,
                blend_maps,
                lightmap,
                triplanar,
            } => {
                let mut d = vec!["MATERIAL"];
                for (on, name) in [
                    (normal_maps, "NORMAL_MAPS"),
                    (blend_maps, "BLEND_MAPS"),
                    (lightmap, "LIGHTMAP"),
                    (triplanar, "TRIPLANAR"),
                ] {
                    if on {
                        d.push(name);
                    }
                }
                d
            }
        }
    }
}

/// What a level of the occlusion pyramid is reduced from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HizSource {
    /// A single-sample depth attachment.
    Depth,
    /// A multisampled depth attachment: every sample of a pixel.
    DepthMultisampled,
    /// The pyramid's level below.
    Pyramid,
}

impl HizSource {
    pub const ALL: [HizSource; 3] = [
        HizSource::Depth,
        HizSource::DepthMultisampled,
        HizSource::Pyramid,
    ];
}

/// One compiled shader: a stage of glsl/ with its features.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Shader {
    TerrainVert,
    TerrainTesc,
    /// `equal_spacing`: whole factors for the error LOD; otherwise
    /// fractional even spacing.
    TerrainTese {
        placing: Placing,
        equal_spacing: bool,
    },
    TerrainFrag(Shading),
    GeomipVert(Placing),
    BruteVert(Placing),
    SkyVert,
    SkyFrag,
    MirrorCheckComp,
    /// One level of the occlusion pyramid.
    HizComp(HizSource),
    /// The occlusion test of every patch.
    OcclusionComp,
    /// The instance counts of the CPU's draw list for a phase.
    OcclusionDrawsComp,
    /// The occlusion-culled patches in one colour.
    CulledFrag,
}

impl Shader {
    /// Every variant there is, each compiled by build.rs, in the order of
    /// the table it writes.
    pub fn all() -> Vec<Shader> {
        let mut all = vec![Shader::TerrainVert, Shader::TerrainTesc];
        for placing in Placing::ALL {
            for equal_spacing in [false, true] {
                all.push(Shader::TerrainTese {
                    placing,
                    equal_spacing,
                });
            }
            all.push(Shader::GeomipVert(placing));
            all.push(Shader::BruteVert(placing));
        }
        for shading in Shading::all() {
            all.push(Shader::TerrainFrag(shading));
        }
        all.push(Shader::SkyVert);
        all.push(Shader::SkyFrag);
        all.push(Shader::MirrorCheckComp);
        for source in HizSource::ALL {
            all.push(Shader::HizComp(source));
        }
        all.push(Shader::OcclusionComp);
        all.push(Shader::OcclusionDrawsComp);
        all.push(Shader::CulledFrag);
        all
    }

    /// The file in glsl/.
    pub fn file(self) -> &'static str {
        match self {
            Shader::TerrainVert => "terrain.vert",
            Shader::TerrainTesc => "terrain.tesc",
            Shader::TerrainTese { .. } => "terrain.tese",
            Shader::TerrainFrag(_) => "terrain.frag",
            Shader::GeomipVert(_) => "geomip.vert",
            Shader::BruteVert(_) => "brute.vert",
            Shader::SkyVert => "sky.vert",
            Shader::SkyFrag => "sky.frag",
            Shader::MirrorCheckComp => "mirror_check.comp",
            Shader::HizComp(_) => "hiz.comp",
            Shader::OcclusionComp => "occlusion.comp",
            Shader::OcclusionDrawsComp => "occlusion_draws.comp",
            Shader::CulledFrag => "culled.frag",
        }
    }

    /// The macros the file is compiled with (each defined as 1).
    pub fn defines(self) -> Vec<&'static str> {
        match self {
            Shader::TerrainTese {
                placing,
                equal_spacing,
            } => {
                let mut d = placing.defines();
                if equal_spacing {
                    d.push("EQUAL_SPACING");
                }
                d
            }
            Shader::GeomipVert(placing) | Shader::BruteVert(placing) => placing.defines(),
            Shader::TerrainFrag(shading) => shading.defines(),
            Shader::HizComp(HizSource::Depth) => vec!["FROM_DEPTH"],
            Shader::HizComp(HizSource::DepthMultisampled) => vec!["FROM_DEPTH_MS"],
            Shader::HizComp(HizSource::Pyramid) => Vec::new(),
            Shader::TerrainVert
            | Shader::TerrainTesc
            | Shader::SkyVert
            | Shader::SkyFrag
            | Shader::MirrorCheckComp
            | Shader::OcclusionComp
            | Shader::OcclusionDrawsComp
            | Shader::CulledFrag => Vec::new(),
        }
    }

    /// A name for the compiled file: "terrain.frag+MATERIAL+LIGHTMAP".
    pub fn key(self) -> String {
        std::iter::once(self.file())
            .chain(self.defines())
            .collect::<Vec<_>>()
            .join("+")
    }
}
