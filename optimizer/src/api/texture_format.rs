//! Texture formats of baked impostor atlases and their GPU memory.

use std::fmt;
use std::str::FromStr;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::api::job::MemoryParams;

/// How baked atlases are stored, which decides their GPU memory per texel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum TextureFormat {
    /// PNG images, uploaded as RGBA8: 4 bytes per texel.
    #[default]
    Png,
    /// KTX2 with Basis Universal UASTC content (`KHR_texture_basisu`),
    /// transcoded to ASTC 4×4 or BC7 on load: 1 byte per texel.
    Ktx2,
}

impl TextureFormat {
    /// Every format, in the order the command line lists them.
    pub const ALL: [TextureFormat; 2] = [TextureFormat::Png, TextureFormat::Ktx2];

    /// GPU bytes per texel of level 0 once uploaded (RGBA8: 4; UASTC as
    /// ASTC 4×4 or BC7: 16-byte blocks of 4 × 4 texels, 1).
    pub fn gpu_bytes_per_texel(self) -> f64 {
        match self {
            TextureFormat::Png => 4.0,
            TextureFormat::Ktx2 => 1.0,
        }
    }

    /// The name used in jobs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            TextureFormat::Png => "png",
            TextureFormat::Ktx2 => "ktx2",
        }
    }
}

impl fmt::Display for TextureFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for TextureFormat {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        TextureFormat::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| format!("unknown texture format '{s}' (expected png or ktx2)"))
    }
}

impl MemoryParams {
    /// GPU bytes per texel of level 0 in the memory model: the texture
    /// format's when the job names one, else `bytes_per_texel`.
    pub fn texel_bytes(&self) -> f64 {
        self.texture_format
            .map_or(self.bytes_per_texel, TextureFormat::gpu_bytes_per_texel)
    }

    /// GPU bytes per texel of atlases baked as `baked`: KTX2's always; PNG's
    /// under the memory model (RGBA8 when the job names a format, else
    /// `bytes_per_texel`, which may model another upload).
    pub fn baked_texel_bytes(&self, baked: TextureFormat) -> f64 {
        match (baked, self.texture_format) {
            (TextureFormat::Png, None) => self.bytes_per_texel,
            (f, _) => f.gpu_bytes_per_texel(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_memory_model_counts_the_named_format() {
        let mut m = MemoryParams::default();
        assert_eq!(m.texel_bytes(), 4.0);
        m.bytes_per_texel = 2.0;
        assert_eq!(m.texel_bytes(), 2.0);
        assert_eq!(m.baked_texel_bytes(TextureFormat::Png), 2.0);
        assert_eq!(m.baked_texel_bytes(TextureFormat::Ktx2), 1.0);
        m.texture_format = Some(TextureFormat::Ktx2);
        assert_eq!(m.texel_bytes(), 1.0);
        assert_eq!(m.baked_texel_bytes(TextureFormat::Png), 4.0);
        // A job without the field reads and writes as before.
        let j: MemoryParams = serde_json::from_str("{}").unwrap();
        assert_eq!(j.texture_format, None);
        assert!(
            !serde_json::to_string(&j)
                .unwrap()
                .contains("texture_format")
        );
        let j: MemoryParams = serde_json::from_str(r#"{"texture_format": "ktx2"}"#).unwrap();
        assert_eq!(j.texture_format, Some(TextureFormat::Ktx2));
        assert!(serde_json::from_str::<MemoryParams>(r#"{"texture_format": "dds"}"#).is_err());
    }

    #[test]
    fn names_parse_back_and_unknown_ones_are_refused() {
        for f in TextureFormat::ALL {
            assert_eq!(f.name().parse::<TextureFormat>(), Ok(f));
            assert_eq!(serde_json::to_value(f).unwrap(), f.name());
        }
        let e = "dds".parse::<TextureFormat>().unwrap_err();
        assert!(e.contains("dds") && e.contains("png or ktx2"), "{e}");
        assert!(serde_json::from_str::<TextureFormat>("\"KTX2\"").is_err());
    }
}
