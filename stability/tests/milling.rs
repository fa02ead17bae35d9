//! Milling lobes: the one-DOF benchmark of Insperger and Stépán, the zeroth-order approximation
//! against the semi-discretization on a two-mode structure, and where they part at low
//! immersion.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use nalgebra::Vector3;
use stability::cut::{Direction, Milling};
use stability::lobes::{self, Process};
use stability::sd::{self, ModalModel, ViscousMode};

fn cutter(teeth: usize, radial_ratio: f64, direction: Direction) -> Milling {
    Milling {
        teeth,
        diameter: 0.02,
        radial_depth: 0.02 * radial_ratio,
        direction,
        feed: Vector3::x(),
        axis: Vector3::z(),
    }
}

fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64))
        .collect()
}

/// ZOA boundary of a modal model.
fn zoa(model: &ModalModel, m: &Milling, kt: f64, kr: f64, speeds: &[f64]) -> Vec<f64> {
    let f: Vec<f64> = model.modes.iter().map(|m| m.freq_hz).collect();
    let lo = f.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = f.iter().copied().fold(0.0, f64::max);
    let frf = model.frf(&log_grid(0.6 * lo, 1.6 * hi, 20000));
    let process = Process::milling(m, kt, kr);
    let br = lobes::branches(&process, &frf);
    lobes::boundary(&br, m.teeth, speeds)
        .iter()
        .map(|p| p.depth)
        .collect()
}

fn linspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
        .collect()
}

/// Insperger & Stépán, "Updated semi-discretization method for periodic delay-differential
/// equations with discrete delay", Int. J. Numer. Meth. Engng 61 (2004) 117–141, the one-DOF
/// milling benchmark (also Insperger, Stépán & Turi 2008; Ding et al. 2010): a 2-tooth cutter,
/// K_t = 6·10⁸ N/m², K_n = 2·10⁸ N/m², ω_n = 2π·922 rad/s, ζ = 0.011, m = 0.03993 kg, slotting.
///
/// For slotting with one DOF along the feed the zeroth-order approximation has a closed form:
/// `A₀,xx = −N K_n / (2 K_t)`, so `G = (N K_n / 4) Φ_xx` and the lowest stable depth is
/// `a_min = 8 k ζ (1 + ζ) / (N K_n) = 0.2981 mm` (k = m ω_n² = 1.3400·10⁶ N/m), at the
/// chatter frequency `f_n √(1 + 2ζ) = 932.1 Hz` where `Re Φ` is lowest; its lobe bottoms
/// lie at `n_k = 60 f_c / (N (ε/2π + k))` with `ε/2π = 0.7517`: 15 957, 10 157, 7 452 rpm for
/// k = 1, 2, 3. The semi-discretization must reproduce the Hopf lobes' minimum depth and their
/// positions (it adds the period-doubling lobes at the highest speeds, which the averaging
/// cannot see).
#[test]
fn one_dof_benchmark_of_insperger_and_stepan() {
    let (kt, kn) = (6.0e8, 2.0e8);
    let model = ModalModel::single(0.03993, 922.0, 0.011);
    let m = cutter(2, 1.0, Direction::Up);
    let k = 0.03993 * (2.0 * std::f64::consts::PI * 922.0_f64).powi(2);
    let a_min = 8.0 * k * 0.011 * 1.011 / (2.0 * kn);
    assert!((a_min - 2.981e-4).abs() < 1e-7, "closed form {a_min}");

    // ZOA on the grid reproduces its own closed form.
    let speeds = linspace(5000.0, 20000.0, 301);
    let z = zoa(&model, &m, kt, kn, &speeds);
    let zmin = z.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(
        (zmin - a_min).abs() < 0.005 * a_min,
        "ZOA minimum {zmin} vs closed form {a_min}"
    );
    // Lobe bottoms where the closed form puts them: the lowest point near each n_k.
    let eps = 0.7517;
    for lobe in 1..=3 {
        let nk = 60.0 * 922.0 * 1.022_f64.sqrt() / (2.0 * (eps + lobe as f64));
        let near: Vec<(f64, f64)> = speeds
            .iter()
            .zip(&z)
            .filter(|(s, _)| (**s - nk).abs() < 0.08 * nk)
            .map(|(s, d)| (*s, *d))
            .collect();
        let best = near.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
        assert!(
            (best.0 - nk).abs() < 0.01 * nk,
            "lobe {lobe}: ZOA bottom at {} rpm, closed form {nk:.0} rpm",
            best.0
        );

        // The semi-discretization's minimum over the same neighbourhood: the same depth and
        // place within the averaging's error.
        let local = linspace(0.94 * nk, 1.06 * nk, 13);
        let sdb = sd::boundary(&model, &m, kt, kn, &local, 4.0 * a_min, 40);
        let (i, smin) = sdb
            .iter()
            .copied()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        assert!(
            (smin - a_min).abs() < 0.10 * a_min,
            "lobe {lobe}: SD minimum {smin} vs ZOA {a_min}"
        );
        assert!(
            (local[i] - nk).abs() < 0.03 * nk,
            "lobe {lobe}: SD bottom at {} rpm vs {nk:.0}",
            local[i]
        );
    }
}

/// A two-mode structure (x: 600 Hz, y: 660 Hz), a 4-tooth cutter in half-immersion down
/// milling: the zeroth-order approximation holds there (several teeth in the cut, the
/// directional matrix's harmonics are small), so its lobes agree with the semi-discretization;
/// in 5 % immersion it does not: the force is a train of short pulses, and the
/// semi-discretization finds the flip (period-doubling) lobes and the raised Hopf lobes the
/// average cannot.
#[test]
fn zoa_agrees_with_semi_discretization_where_it_holds_and_not_at_low_immersion() {
    let model = ModalModel {
        modes: vec![
            ViscousMode {
                freq_hz: 600.0,
                damping_ratio: 0.035,
                shape: [1.0 / 2.0_f64.sqrt(), 0.0],
            },
            ViscousMode {
                freq_hz: 660.0,
                damping_ratio: 0.03,
                shape: [0.0, 1.0 / 2.5_f64.sqrt()],
            },
        ],
    };
    let (kt, kr) = (6.0e8, 2.0e8);
    let speeds = linspace(6000.0, 14000.0, 17);

    let half = cutter(4, 0.5, Direction::Down);
    let z = zoa(&model, &half, kt, kr, &speeds);
    let zmax = z.iter().copied().fold(0.0, f64::max);
    let s = sd::boundary(&model, &half, kt, kr, &speeds, 1.5 * zmax, 40);
    let zmin = z.iter().copied().fold(f64::INFINITY, f64::min);
    let smin = s.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(
        (zmin - smin).abs() < 0.08 * smin,
        "half immersion: minimum depth ZOA {zmin} vs SD {smin}"
    );
    for (i, (a, b)) in z.iter().zip(&s).enumerate() {
        assert!(
            (a - b).abs() < 0.25 * b,
            "half immersion at {} rpm: ZOA {a} vs SD {b}",
            speeds[i]
        );
    }

    let low = cutter(4, 0.05, Direction::Down);
    let z = zoa(&model, &low, kt, kr, &speeds);
    let zmax = z.iter().copied().fold(0.0, f64::max);
    let s = sd::boundary(&model, &low, kt, kr, &speeds, 1.5 * zmax, 40);
    let worst = z
        .iter()
        .zip(&s)
        .map(|(a, b)| (a / b).max(b / a))
        .fold(0.0, f64::max);
    assert!(
        worst > 1.5,
        "5 % immersion: ZOA and SD should part somewhere (largest ratio {worst})"
    );
}

/// The modal model of an RFE model (undamped modes, ζ = η/2) has the oriented FRF of the
/// hysteretic model at its resonances, where chatter is.
#[test]
fn the_modal_model_of_an_rfe_model_matches_its_frf_at_resonance() {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let model = rfe::modelfile::load(&root.join("configs/models/textbook-two-mass.toml"))
        .unwrap()
        .model;
    let cut =
        stability::cut::load(&root.join("configs/cuts/textbook-two-mass-turning.toml")).unwrap();
    let placement = stability::oriented::place(&model, &cut).unwrap();
    let modal = ModalModel::of_placement(&placement, 1.0e4).unwrap();
    // The chain's two axial modes carry the z motion.
    let axial: Vec<&ViscousMode> = modal
        .modes
        .iter()
        .filter(|m| m.shape[0].abs() > 1e-6)
        .collect();
    assert_eq!(axial.len(), 2, "{:?}", modal.modes);
    for m in axial {
        let f = [m.freq_hz];
        let ours = modal.frf(&f).phi[0][0][0];
        let rfe =
            stability::oriented::oriented_frf(&placement, &cut, &f, None, rfe::frf::Method::Direct)
                .unwrap()
                .phi[0][0][0];
        assert!(
            (ours - rfe).norm() < 0.05 * rfe.norm(),
            "{} Hz: modal {ours} vs RFE {rfe}",
            m.freq_hz
        );
    }
}
