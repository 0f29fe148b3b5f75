//! Where a training iteration's time goes: wall-clock seconds per phase, accumulated over the
//! iterations of a run and written beside the losses (`profile.csv`) so that speed work is
//! aimed at what costs, and anyone can re-measure it on their machine.
//!
//! The timers bracket whole phases of [`super::Trainer::step`] and
//! [`super::Trainer::warm_step`]; `Instant::now` costs tens of nanoseconds, so they stay on.

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

/// Accumulated time per phase, for the warm start and the image-loss iterations separately.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepProfile {
    warm: [Duration; Phase::ALL.len()],
    image: [Duration; Phase::ALL.len()],
    warm_iterations: u64,
    image_iterations: u64,
}

/// Which kind of iteration a timing belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IterationKind {
    /// A warm-start iteration.
    Warm,
    /// An image-loss iteration.
    Image,
}

impl StepProfile {
    /// Adds `elapsed` to `phase` of `kind`.
    pub fn add(&mut self, kind: IterationKind, phase: Phase, elapsed: Duration) {
        let slot = Phase::ALL.iter().position(|&p| p == phase).unwrap_or(0);
        match kind {
            IterationKind::Warm => self.warm[slot] += elapsed,
            IterationKind::Image => self.image[slot] += elapsed,
        }
    }

    /// Counts one finished iteration of `kind`.
    pub fn finish_iteration(&mut self, kind: IterationKind) {
        match kind {
            IterationKind::Warm => self.warm_iterations += 1,
            IterationKind::Image => self.image_iterations += 1,
        }
    }

    /// Mean seconds per iteration of `kind` spent in `phase` (0 without iterations).
    #[must_use]
    pub fn mean_seconds(&self, kind: IterationKind, phase: Phase) -> f64 {
        let slot = Phase::ALL.iter().position(|&p| p == phase).unwrap_or(0);
        let (total, n) = match kind {
            IterationKind::Warm => (self.warm[slot], self.warm_iterations),
            IterationKind::Image => (self.image[slot], self.image_iterations),
        };
        if n == 0 {
            0.0
        } else {
            total.as_secs_f64() / n as f64
        }
    }

    /// Iterations of `kind` timed so far.
    #[must_use]
    pub fn iterations(&self, kind: IterationKind) -> u64 {
        match kind {
            IterationKind::Warm => self.warm_iterations,
            IterationKind::Image => self.image_iterations,
        }
    }

    /// `kind,iterations,phase,ms_per_iteration` rows for both kinds, with a header.
    #[must_use]
    pub fn csv(&self) -> String {
        let mut out = String::from("kind,iterations,phase,ms_per_iteration\n");
        for (kind, name) in [
            (IterationKind::Warm, "warm"),
            (IterationKind::Image, "image"),
        ] {
            let n = self.iterations(kind);
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
    }

    #[test]
    fn an_empty_profile_reports_zeros() {
        let p = StepProfile::default();
        assert_eq!(p.iterations(IterationKind::Warm), 0);
        assert!(p.csv().contains("warm,0,total,0.000\n"));
    }
}
