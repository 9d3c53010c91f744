//! `bake --textures ktx2`: KTX2 (Basis Universal UASTC) atlases behind
//! `KHR_texture_basisu` that the Khronos validator accepts, that decode
//! back to the PNG bake's atlases and that `evaluate --impostors` reads.

use optimizer::bake::ktx2::{decode_uastc, masked_psnr_db as psnr};
use optimizer::bake::mips::coverage;

use crate::util::*;

/// Runs `bake` with `--textures FORMAT`.
fn bake_as(
    scene: &std::path::Path,
    p: &std::path::Path,
    job: &std::path::Path,
    glb: &std::path::Path,
    report: &std::path::Path,
    format: &str,
) -> std::process::Output {
    bake_with(scene, p, job, glb, report, &["--textures", format])
}

/// The JSON document and binary chunk of a GLB.
fn glb_parts(bytes: &[u8]) -> (serde_json::Value, Vec<u8>) {
    let glb = gltf::binary::Glb::from_slice(bytes).expect("a GLB");
    let json = serde_json::from_slice(&glb.json).expect("GLB JSON");
    (json, glb.bin.expect("a binary chunk").into_owned())
}

#[test]
fn ktx2_bake_validates_and_decodes_to_the_png_atlases() {
    let dir = tmp("bake-ktx2");
    let city = city("0.1");
    let job = root().join("fixtures/jobs/city-small-flyover.json");
    let p = dir.join("p.json");
    let o = place(&city, &job, &p, &[]);
    assert!(matches!(code(&o), 0 | 3), "{}", stderr(&o));
    let (png_glb, png_rep) = (dir.join("png.glb"), dir.join("png.json"));
    let o = bake_as(&city, &p, &job, &png_glb, &png_rep, "png");
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let (ktx_glb, ktx_rep) = (dir.join("ktx2.glb"), dir.join("ktx2.json"));
    let o = bake_as(&city, &p, &job, &ktx_glb, &ktx_rep, "ktx2");
    assert_eq!(code(&o), 0, "{}", stderr(&o));

    // The memory model: UASTC is 1 GPU byte per texel, RGBA8 4.
    let (png, ktx) = (read_json(&png_rep), read_json(&ktx_rep));
    assert_eq!(
        (
            png["texture_format"].as_str(),
            ktx["texture_format"].as_str()
        ),
        (Some("png"), Some("ktx2"))
    );
    assert_eq!(png["texels"], ktx["texels"]);
    let (pm, km) = (
        png["memory_bytes"].as_u64().unwrap(),
        ktx["memory_bytes"].as_u64().unwrap(),
    );
    assert!(
        km > 0 && pm.abs_diff(4 * km) <= 4,
        "png {pm} B, ktx2 {km} B"
    );

    // The Khronos validator accepts the file.
    let issues = crate::bake::validate(&ktx_glb);
    assert_eq!(issues["numErrors"], 0, "{issues}");
    // Its 2.0.0-dev.3.10 does not know KHR_texture_basisu: it warns only
    // that it cannot read the KTX2 images (so the decoding below is the
    // check of their content), nothing else.
    for m in issues["messages"].as_array().unwrap() {
        if m["severity"].as_u64() <= Some(1) {
            let code = m["code"].as_str().unwrap();
            assert!(
                ["VALUE_NOT_IN_LIST", "IMAGE_UNRECOGNIZED_FORMAT"].contains(&code)
                    && m["pointer"].as_str().unwrap().starts_with("/images/"),
                "{m}"
            );
        }
    }

    // The document: KTX2 images behind a required KHR_texture_basisu.
    let bytes = std::fs::read(&ktx_glb).unwrap();
    let (doc, bin) = glb_parts(&bytes);
    assert_eq!(
        doc["extensionsRequired"],
        serde_json::json!(["KHR_texture_basisu"])
    );
    assert!(
        doc["extensionsUsed"]
            .as_array()
            .unwrap()
            .contains(&"KHR_texture_basisu".into())
    );
    let textures = doc["textures"].as_array().unwrap();
    assert_eq!(textures.len() as u64, ktx["atlases"].as_u64().unwrap());

    // The PNG bake's atlases, decoded by the scene loader.
    let png_geom = optimizer::scene::geometry::load_geometry_bytes(
        &std::fs::read(&png_glb).unwrap(),
        "png.glb",
    )
    .unwrap();
    assert_eq!(png_geom.textures.len(), textures.len());
    for (i, t) in textures.iter().enumerate() {
        assert!(t.get("source").is_none(), "{t}");
        let image = &doc["images"][t["extensions"]["KHR_texture_basisu"]["source"]
            .as_u64()
            .unwrap() as usize];
        assert_eq!(image["mimeType"], "image/ktx2");
        let view = &doc["bufferViews"][image["bufferView"].as_u64().unwrap() as usize];
        let at = view["byteOffset"].as_u64().unwrap() as usize;
        let file = &bin[at..at + view["byteLength"].as_u64().unwrap() as usize];
        let r = ktx2::Reader::new(file).expect("a KTX2 file");
        let h = r.header();
        let atlas = &png_geom.textures[i];
        assert_eq!((h.pixel_width, h.pixel_height), (atlas.width, atlas.height));
        assert_eq!(r.color_model(), Some(ktx2::ColorModel::UASTC));
        // A full chain down to 1 × 1.
        assert_eq!(
            h.level_count,
            32 - atlas.width.max(atlas.height).leading_zeros()
        );
        let levels: Vec<_> = r.levels().collect();
        let level0 = decode_uastc(levels[0].data, h.pixel_width, h.pixel_height).unwrap();
        // 35 dB (an RMS error under 4.6 of 255): block artefacts stay
        // below what a masked, filtered impostor shows, while a misplaced
        // or misdecoded level falls below 25 dB (the control).
        let q = psnr(&level0, &atlas.rgba);
        assert!(q > 35.0, "atlas {i}: {q:.1} dB");
        let row = (atlas.width * 4) as usize;
        let flipped: Vec<u8> = atlas
            .rgba
            .chunks_exact(row)
            .rev()
            .flatten()
            .copied()
            .collect();
        assert!(
            psnr(&level0, &flipped) < 25.0,
            "the control matches: the check proves nothing"
        );
        // Alpha coverage holds down the chain (levels down to 64 texels wide).
        let c0 = coverage(&atlas.rgba, 0.5);
        for (k, l) in levels.iter().enumerate().skip(1) {
            let (w, hh) = ((h.pixel_width >> k).max(1), (h.pixel_height >> k).max(1));
            if w < 64 || hh < 64 {
                break;
            }
            let c = coverage(&decode_uastc(l.data, w, hh).unwrap(), 0.5);
            assert!(
                (c - c0).abs() <= 0.05 * c0 + 1e-3,
                "atlas {i} level {k}: coverage {c} vs {c0}"
            );
        }
    }

    // This tool's own readers take the KTX2 bake as they take the PNG one
    // (level 0 decoded): the same layers, and `evaluate --images
    // --impostors` sees nearly the PNG bake's image error (UASTC's block
    // error adds a little), far from its magenta control.
    let layers = |glb: &std::path::Path| {
        optimizer::bake::read_layers(&std::fs::read(glb).unwrap(), "baked").unwrap()
    };
    let (png_layers, ktx_layers) = (layers(&png_glb), layers(&ktx_glb));
    assert_eq!(png_layers.len(), ktx_layers.len());
    for (a, b) in png_layers.iter().zip(&ktx_layers) {
        assert_eq!((a.impostor, a.index, a.res), (b.impostor, b.index, b.res));
        assert_eq!(a.corners, b.corners);
    }
    let image = |glb: &std::path::Path, name: &str| {
        let out = dir.join(name);
        let o = evaluate_with(
            &city,
            &job,
            &p,
            &out,
            50,
            &["--images", "24", "--impostors", s(glb)],
        );
        assert_eq!(code(&o), 0, "{}", stderr(&o));
        read_json(&out)["image"].clone()
    };
    let (png_image, ktx_image) = (
        image(&png_glb, "e-png.json"),
        image(&ktx_glb, "e-ktx2.json"),
    );
    let mean = |i: &serde_json::Value, k: &str| i[k]["mean"].as_f64().unwrap();
    assert!(ktx_image["views"].as_u64().unwrap() >= 10, "{ktx_image}");
    assert_eq!(ktx_image["views"], png_image["views"]);
    let (pm, km) = (
        mean(&png_image, "footprint_mismatch_fraction"),
        mean(&ktx_image, "footprint_mismatch_fraction"),
    );
    assert!(km <= pm + 0.02, "KTX2 mismatch {km} against PNG {pm}");
    assert!(
        mean(&ktx_image, "control_mismatch_fraction") > 10.0 * km,
        "{ktx_image}"
    );

    // Deterministic: the same bake gives the same bytes.
    let again = dir.join("ktx2-again.glb");
    let o = bake_as(&city, &p, &job, &again, &dir.join("again.json"), "ktx2");
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert_same_file(&ktx_glb, &again);

    // A bad format is a clear error.
    let o = bake_as(
        &city,
        &p,
        &job,
        &dir.join("x.glb"),
        &dir.join("x.json"),
        "dds",
    );
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(
        stderr(&o).contains("dds") && stderr(&o).contains("png or ktx2"),
        "{}",
        stderr(&o)
    );
}
