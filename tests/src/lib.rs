//! Workspace integration tests live in `tests/tests/`; this library only shares helpers.

use std::path::Path;

use skinfield_formats::capture::{Capture, load_capture};
use skinfield_formats::skf::SkfModel;
use skinfield_trainer::synth::{SynthConfig, synthesize};
use skinfield_trainer::train::data::{DataOptions, initial_weights, train_data};
use skinfield_trainer::train::{TrainConfig, Trainer};

/// The tiny synthetic capture written into `dir`, and a SkinNet trained on it for `warm`
/// warm-start and `image` silhouette iterations, exported as `trainer train` does (with its
/// candidate joints). A high learning rate makes a few iterations leave the near-uniform
/// initialisation, so the weights are really trained ones. Panics on failure (test helper).
#[must_use]
pub fn tiny_trained_model(dir: &Path, warm: u64, image: u64) -> (Capture, SkfModel) {
    synthesize(dir, &SynthConfig::tiny()).expect("synthesize");
    let capture = load_capture(dir).expect("load the capture");
    let initial = initial_weights(&capture).expect("initial weights");
    let data = train_data(&capture, &initial, &DataOptions::default()).expect("training data");
    let config = TrainConfig {
        warm_start_iterations: warm,
        iterations: image,
        batch: 2,
        adam: skinfield_trainer::optim::AdamConfig {
            lr: 1e-2,
            ..Default::default()
        },
        ..TrainConfig::default()
    };
    let mut trainer = Trainer::new(data, config, false).expect("trainer");
    for _ in 0..warm {
        trainer.warm_step().expect("warm step");
    }
    for _ in 0..image {
        trainer.step().expect("step");
    }
    (capture, trainer.skf_model().expect("export"))
}
