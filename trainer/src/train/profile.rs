//! Where a training iteration's time goes: wall-clock seconds per phase, accumulated over the
//! iterations of a run and written beside the losses (`profile.csv`) so that speed work is
//! aimed at what costs, and anyone can re-measure it on their machine.
//!
//! The timers bracket whole phases of [`super::Trainer::step`] and
//! [`super::Trainer::warm_step`]; `Instant::now` costs tens of nanoseconds, so they stay on.
//! The file is written after stage 1 and again after stage 4, with one block of rows per
//! [`IterationKind`].

use std::time::{Duration, Instant};

/// A phase of one training iteration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Phase {
    /// SkinNet's forward pass (or the static baseline's softmax), query-row selection included.
    Forward,
    /// Linear blend skinning of the batch and the initial-weight posing the losses compare with.
    Skinning,
    /// Projection, boundary vertices (coverage raster + its distance transform), nearest
    /// contour matches and the distance samples of every view.
    Silhouette,
    /// Laplacian, geodesic and part-wise regularisers, and the warm start's KL.
    Regularisers,
    /// Stage 4's rendering term.
    Rendering,
    /// Back-propagation through the whole graph.
    Backward,
    /// Gradient clipping and the Adam update.
    Optimiser,
}

impl Phase {
    /// Every phase, in the order of an iteration.
    pub const ALL: [Phase; 7] = [
        Phase::Forward,
        Phase::Skinning,
        Phase::Silhouette,
        Phase::Regularisers,
        Phase::Rendering,
        Phase::Backward,
        Phase::Optimiser,
    ];

    /// The phase's name in `profile.csv`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Phase::Forward => "forward",
            Phase::Skinning => "skinning",
            Phase::Silhouette => "silhouette",
            Phase::Regularisers => "regularisers",
            Phase::Rendering => "rendering",
            Phase::Backward => "backward",
            Phase::Optimiser => "optimiser",
        }
    }
}

/// Accumulated time per phase, for each kind of iteration separately.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepProfile {
    totals: [[Duration; Phase::ALL.len()]; IterationKind::ALL.len()],
    iterations: [u64; IterationKind::ALL.len()],
}

/// Which kind of iteration a timing belongs to. The kinds cost very different amounts (stage 4
/// poses the full-resolution template), so one average over all of them would describe none.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IterationKind {
    /// A warm-start iteration.
    Warm,
    /// An image-loss iteration of stage 1 (or of the static baseline).
    Image,
    /// An image-loss iteration of stage 4 (after stage 1's iterations, with or without the
    /// rendering term).
    Refine,
}

impl IterationKind {
    /// Every kind, in the order of a run.
    pub const ALL: [IterationKind; 3] = [
        IterationKind::Warm,
        IterationKind::Image,
        IterationKind::Refine,
    ];

    /// The kind's name in `profile.csv`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            IterationKind::Warm => "warm",
            IterationKind::Image => "image",
            IterationKind::Refine => "refine",
        }
    }

    fn slot(self) -> usize {
        self as usize
    }
}

impl Phase {
    fn slot(self) -> usize {
        self as usize
    }
}

impl StepProfile {
    /// Adds `elapsed` to `phase` of `kind`.
    pub fn add(&mut self, kind: IterationKind, phase: Phase, elapsed: Duration) {
        self.totals[kind.slot()][phase.slot()] += elapsed;
    }

    /// Counts one finished iteration of `kind`.
    pub fn finish_iteration(&mut self, kind: IterationKind) {
        self.iterations[kind.slot()] += 1;
    }

    /// Mean seconds per iteration of `kind` spent in `phase` (0 without iterations).
    #[must_use]
    pub fn mean_seconds(&self, kind: IterationKind, phase: Phase) -> f64 {
        let n = self.iterations(kind);
        if n == 0 {
            0.0
        } else {
            self.totals[kind.slot()][phase.slot()].as_secs_f64() / n as f64
        }
    }

    /// Iterations of `kind` timed so far.
    #[must_use]
    pub fn iterations(&self, kind: IterationKind) -> u64 {
        self.iterations[kind.slot()]
    }

    /// `kind,iterations,phase,ms_per_iteration` rows for every kind, with a header.
    #[must_use]
    pub fn csv(&self) -> String {
        let mut out = String::from("kind,iterations,phase,ms_per_iteration\n");
        for kind in IterationKind::ALL {
            let (name, n) = (kind.name(), self.iterations(kind));
            let mut total = 0.0;
            for phase in Phase::ALL {
                let ms = 1e3 * self.mean_seconds(kind, phase);
                total += ms;
                out.push_str(&format!("{name},{n},{},{ms:.3}\n", phase.name()));
            }
            out.push_str(&format!("{name},{n},total,{total:.3}\n"));
        }
        out
    }
}

/// Times one phase: `let t = Timer::start(); …; t.stop(profile, kind, phase)`.
#[derive(Clone, Copy, Debug)]
pub struct Timer(Instant);

impl Timer {
    /// Starts the clock.
    #[must_use]
    pub fn start() -> Self {
        Self(Instant::now())
    }

    /// Adds the time since [`Timer::start`] to `phase` and restarts the clock (so consecutive
    /// phases can share one timer).
    pub fn lap(&mut self, profile: &mut StepProfile, kind: IterationKind, phase: Phase) {
        let now = Instant::now();
        profile.add(kind, phase, now - self.0);
        self.0 = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn means_are_per_iteration_and_per_kind() {
        let mut p = StepProfile::default();
        p.add(
            IterationKind::Image,
            Phase::Backward,
            Duration::from_millis(30),
        );
        p.add(
            IterationKind::Image,
            Phase::Backward,
            Duration::from_millis(10),
        );
        p.add(
            IterationKind::Warm,
            Phase::Forward,
            Duration::from_millis(5),
        );
        p.finish_iteration(IterationKind::Image);
        p.finish_iteration(IterationKind::Image);
        p.finish_iteration(IterationKind::Warm);
        assert!((p.mean_seconds(IterationKind::Image, Phase::Backward) - 0.020).abs() < 1e-9);
        assert_eq!(p.mean_seconds(IterationKind::Image, Phase::Forward), 0.0);
        assert!((p.mean_seconds(IterationKind::Warm, Phase::Forward) - 0.005).abs() < 1e-9);
        let csv = p.csv();
        assert!(csv.contains("image,2,backward,20.000\n"), "{csv}");
        assert!(csv.contains("image,2,total,20.000\n"), "{csv}");
        assert!(csv.contains("warm,1,forward,5.000\n"), "{csv}");
        assert!(csv.contains("refine,0,total,0.000\n"), "{csv}");
    }

    #[test]
    fn slots_follow_the_order_of_all() {
        for (i, p) in Phase::ALL.iter().enumerate() {
            assert_eq!(p.slot(), i);
        }
        for (i, k) in IterationKind::ALL.iter().enumerate() {
            assert_eq!(k.slot(), i);
        }
    }

    #[test]
    fn the_kinds_are_kept_apart() {
        let mut p = StepProfile::default();
        for (kind, ms) in [
            (IterationKind::Warm, 1),
            (IterationKind::Image, 10),
            (IterationKind::Refine, 100),
        ] {
            p.add(kind, Phase::Forward, Duration::from_millis(ms));
            p.finish_iteration(kind);
        }
        for (kind, s) in [
            (IterationKind::Warm, 0.001),
            (IterationKind::Image, 0.010),
            (IterationKind::Refine, 0.100),
        ] {
            assert_eq!(p.iterations(kind), 1);
            assert!(
                (p.mean_seconds(kind, Phase::Forward) - s).abs() < 1e-9,
                "{kind:?}"
            );
        }
        let csv = p.csv();
        let kinds: Vec<&str> = csv
            .lines()
            .skip(1)
            .filter(|l| l.contains(",total,"))
            .map(|l| l.split(',').next().unwrap_or(""))
            .collect();
        assert_eq!(kinds, ["warm", "image", "refine"], "{csv}");
    }

    #[test]
    fn an_empty_profile_reports_zeros() {
        let p = StepProfile::default();
        assert_eq!(p.iterations(IterationKind::Warm), 0);
        assert!(p.csv().contains("warm,0,total,0.000\n"));
    }
}
