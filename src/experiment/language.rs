//! The experiment language's properties, node by node: the schemas of the
//! nodes the parser reads itself (`scene`, `camera`, `render`, `measured`)
//! and, gathered from the stages that read them, every other node's
//! (`lens`, `sensor`, `add`, `override`, each `measure` kind). `camsim params`
//! prints them; the language reference's tables are that output, and the
//! parameter-reach test iterates over [`schemas`].

use crate::params::{Kind, ParamSpec, Schema};

/// `scene "FILE" [materials=…]`.
pub static SCENE_SCHEMA: Schema = Schema {
    node: "scene \"FILE\"",
    params: &[ParamSpec::new(
        "materials",
        Kind::Choice(&["paper", "file"]),
        "file",
        "\"paper\": the paper's measured wall, cube, MCC and lamp spectra replace a pbrt Cornell box's placeholder materials",
        "\"paper\"",
    )],
};

/// `camera position-m=… look-at-m=… [up=…]`.
pub static CAMERA_SCHEMA: Schema = Schema {
    node: "camera",
    params: &[
        ParamSpec::new(
            "position-m",
            Kind::Vec3,
            "",
            "eye position in scene coordinates (required)",
            "(0.013 0.117 -0.41)",
        ),
        ParamSpec::new(
            "look-at-m",
            Kind::Vec3,
            "",
            "a point on the optical axis (required)",
            "(0.021 0.109 0.63)",
        ),
        ParamSpec::new(
            "up",
            Kind::Vec3,
            "(0 1 0)",
            "up direction of the image",
            "(0.05 1 0)",
        ),
    ],
};

/// `render …`.
pub static RENDER_SCHEMA: Schema = Schema {
    node: "render",
    params: &[
        ParamSpec::new("spp", Kind::Integer, "64", "samples per pixel", "37"),
        ParamSpec::new(
            "max-bounces",
            Kind::Integer,
            "5",
            "maximum path length in bounces (0: emitters seen directly)",
            "3",
        ),
        ParamSpec::new(
            "seed",
            Kind::Integer,
            "0",
            "random seed (`camsim run --seed` replaces it)",
            "4242",
        ),
        ParamSpec::new(
            "wavelength-nm",
            Kind::Numbers,
            "(400 700 10)",
            "spectral bands (start stop step)",
            "(410 690 20)",
        ),
        ParamSpec::new(
            "sampler",
            Kind::Choice(&crate::render::SamplerKind::NAMES),
            "sobol",
            "the renderer's random numbers: \"sobol\" stratifies each batch's samples over the pixel, pupil, light and first two bounces (Owen-scrambled Sobol; error falls at least as fast as N^(−½), often faster), \"independent\" draws them independently (error ∝ N^(−½) exactly)",
            "\"independent\"",
        ),
        ParamSpec::new(
            "target-stderr",
            Kind::NumberOr(&["\"N%\""]),
            "none",
            "error-driven sampling: render in rounds (the first of `spp` samples) until every figure's standard error is at most this: a number in each figure's own unit, or \"N%\" of its magnitude; needs max-s or max-spp. `target \"MEASUREMENT\" [quantity=…] stderr=…` children set one measurement's (or figure's) target",
            "\"1%\"",
        ),
        ParamSpec::new(
            "max-s",
            Kind::Number,
            "none",
            "error-driven sampling's wall-time budget (render and measurements of every round); a run it stops is flagged \"time budget\" and depends on the machine's speed",
            "120",
        ),
        ParamSpec::new(
            "max-spp",
            Kind::Integer,
            "none",
            "error-driven sampling's sample budget per pixel (all rounds; deterministic)",
            "4096",
        ),
    ],
};

/// `render { target "MEASUREMENT" … }`.
pub static TARGET_SCHEMA: Schema = Schema {
    node: "target \"MEASUREMENT\" (child of render)",
    params: &[
        ParamSpec::new(
            "stderr",
            Kind::NumberOr(&["\"N%\""]),
            "",
            "the largest standard error of the measurement's figures: a number in each figure's own unit, or \"N%\" of its magnitude (required)",
            "0.5",
        ),
        ParamSpec::new(
            "quantity",
            Kind::Text,
            "all",
            "only this figure of the measurement: its quantity's exact name or a trailing `/…` part of it",
            "\"mtf50\"",
        ),
    ],
};

/// `measured "NAME" file=… …`.
pub static MEASURED_SCHEMA: Schema = Schema {
    node: "measured \"NAME\"",
    params: &[
        ParamSpec::new(
            "file",
            Kind::File,
            "",
            "the captured image: PNG (8/16 bit), OpenEXR or DNG/TIFF (required)",
            "\"capture.png\"",
        ),
        ParamSpec::new(
            "pixel-um",
            Kind::Number,
            "",
            "pixel pitch of the capture (for cy/mm figures)",
            "1.55",
        ),
        ParamSpec::new(
            "labels",
            Kind::File,
            "",
            "grey PNG label map: value k = the object on line k of `names` (needs names)",
            "\"labels.png\"",
        ),
        ParamSpec::new(
            "names",
            Kind::File,
            "",
            "object names of the label map, one a line (needs labels)",
            "\"names.txt\"",
        ),
    ],
};

/// Every node's schema, in the order of the language reference.
pub fn schemas() -> Vec<&'static Schema> {
    let mut v = vec![
        &SCENE_SCHEMA,
        &CAMERA_SCHEMA,
        &crate::scene::camera_params::LENS_FILE_SCHEMA,
        &crate::scene::camera_params::LENS_MODEL_SCHEMA,
        &RENDER_SCHEMA,
        &TARGET_SCHEMA,
        &crate::sensor::SCHEMA,
    ];
    v.extend(
        crate::scene::edits::Target::ALL
            .iter()
            .map(|t| crate::scene::edits::addition_schema(*t)),
    );
    v.push(&crate::scene::edits::OVERRIDE_SCHEMA);
    v.extend(crate::measure::request::schemas());
    v.push(&MEASURED_SCHEMA);
    v.push(&crate::pov::check_params::SCHEMA);
    v.extend(crate::summary::schemas());
    v
}

/// The reference tables of every node (Markdown), as in the language reference.
pub fn markdown() -> String {
    let mut s = String::from(
        "<!-- generated by `camsim params`: edit the schemas in the code, not this table -->\n\n",
    );
    for sc in schemas() {
        s.push_str(&sc.markdown());
        s.push('\n');
    }
    s
}
