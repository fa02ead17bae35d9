//! Stabilization diagram and pole selection.
//!
//! A pole of order `p` is compared with the nearest pole (in frequency) of order `p − 1`: it is
//! stable in frequency when the relative difference is within [`StabilityTolerances::freq`], in
//! damping within [`StabilityTolerances::damping`], and in participation vector when their MAC is
//! at least `1 − `[`StabilityTolerances::participation`]. Automatic selection clusters the fully
//! stable, positively damped poles of the band across orders and keeps the clusters found at
//! enough orders; the user's override picks, for each approximate frequency, the
//! cluster within a window that is found at the most orders.

use super::lscf::{OrderPoles, Pole};
use super::{mac, ModalError, Result};

/// Stability tolerances between consecutive orders.
#[derive(Debug, Clone, Copy)]
pub struct StabilityTolerances {
    /// Relative frequency change (default 0.01).
    pub freq: f64,
    /// Relative damping change (default 0.05).
    pub damping: f64,
    /// `1 − MAC` of the participation vectors (default 0.02).
    pub participation: f64,
}

impl Default for StabilityTolerances {
    fn default() -> Self {
        StabilityTolerances {
            freq: 0.01,
            damping: 0.05,
            participation: 0.02,
        }
    }
}

/// Stability class of a pole in the diagram (the usual symbols in brackets).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Stability {
    /// No counterpart at the previous order (`o`).
    New,
    /// Frequency stable (`f`).
    Frequency,
    /// Frequency and participation vector stable (`v`).
    Vector,
    /// Frequency and damping stable (`d`).
    Damping,
    /// Frequency, damping and participation vector stable (`s`).
    Stable,
}

impl Stability {
    /// One-letter symbol.
    pub fn symbol(self) -> char {
        match self {
            Stability::New => 'o',
            Stability::Frequency => 'f',
            Stability::Vector => 'v',
            Stability::Damping => 'd',
            Stability::Stable => 's',
        }
    }
}

/// The poles of every order with their stability.
#[derive(Debug, Clone)]
pub struct StabilizationDiagram {
    /// Poles per order, increasing order.
    pub orders: Vec<OrderPoles>,
    /// `stability[i][j]`: class of `orders[i].poles[j]`.
    pub stability: Vec<Vec<Stability>>,
    /// The tolerances used.
    pub tolerances: StabilityTolerances,
}

/// Classifies every pole against the previous order.
pub fn stabilize(orders: Vec<OrderPoles>, tol: StabilityTolerances) -> StabilizationDiagram {
    let mut stability = Vec::with_capacity(orders.len());
    for (i, op) in orders.iter().enumerate() {
        let prev = if i > 0 { Some(&orders[i - 1]) } else { None };
        let classes = op
            .poles
            .iter()
            .map(|pole| match prev {
                Some(prev) => classify(pole, &prev.poles, &tol),
                None => Stability::New,
            })
            .collect();
        stability.push(classes);
    }
    StabilizationDiagram {
        orders,
        stability,
        tolerances: tol,
    }
}

fn classify(pole: &Pole, prev: &[Pole], tol: &StabilityTolerances) -> Stability {
    let Some(near) = prev.iter().min_by(|a, b| {
        (a.freq_hz - pole.freq_hz)
            .abs()
            .total_cmp(&(b.freq_hz - pole.freq_hz).abs())
    }) else {
        return Stability::New;
    };
    let f_ok = (pole.freq_hz - near.freq_hz).abs() <= tol.freq * near.freq_hz.abs();
    if !f_ok {
        return Stability::New;
    }
    let d_ok =
        (pole.damping_ratio - near.damping_ratio).abs() <= tol.damping * near.damping_ratio.abs();
    let v_ok = mac(
        std::slice::from_ref(&pole.participation),
        std::slice::from_ref(&near.participation),
    )[0][0]
        >= 1.0 - tol.participation;
    match (d_ok, v_ok) {
        (true, true) => Stability::Stable,
        (true, false) => Stability::Damping,
        (false, true) => Stability::Vector,
        (false, false) => Stability::Frequency,
    }
}

/// Settings of automatic pole selection.
#[derive(Debug, Clone)]
pub struct SelectionSettings {
    /// Only poles in this band (Hz).
    pub band_hz: (f64, f64),
    /// A cluster must hold fully stable poles of at least this many orders.
    pub min_orders: usize,
    /// Poles with a damping ratio above this are left out (default 0.2).
    pub max_damping: f64,
}

/// Clusters the fully stable poles (0 < ζ ≤ max_damping, in the band) across orders and returns
/// one pole per cluster found at `min_orders` orders or more: the member of the highest order.
pub fn select_auto(diagram: &StabilizationDiagram, s: &SelectionSettings) -> Vec<Pole> {
    clusters(diagram, |p| {
        p.damping_ratio <= s.max_damping && p.freq_hz >= s.band_hz.0 && p.freq_hz <= s.band_hz.1
    })
    .into_iter()
    .filter(|c| c.orders >= s.min_orders.max(1))
    .map(|c| c.pole)
    .collect()
}

/// A group of stable poles of nearly the same frequency across orders.
struct Cluster {
    /// Number of distinct orders holding a member.
    orders: usize,
    /// The member of the highest order.
    pole: Pole,
}

/// Fully stable, positively damped poles passing `keep`, sorted by frequency and grouped while
/// within the frequency tolerance of the group's mean.
fn clusters(diagram: &StabilizationDiagram, keep: impl Fn(&Pole) -> bool) -> Vec<Cluster> {
    let tol = diagram.tolerances.freq;
    let mut cand: Vec<(usize, &Pole)> = Vec::new();
    for (op, st) in diagram.orders.iter().zip(&diagram.stability) {
        for (pole, c) in op.poles.iter().zip(st) {
            if *c == Stability::Stable && pole.damping_ratio > 0.0 && keep(pole) {
                cand.push((op.order, pole));
            }
        }
    }
    cand.sort_by(|a, b| a.1.freq_hz.total_cmp(&b.1.freq_hz));
    let mut groups: Vec<(f64, Vec<(usize, &Pole)>)> = Vec::new();
    for c in cand {
        match groups.last_mut() {
            Some((sum, g))
                if (c.1.freq_hz - *sum / g.len() as f64).abs() <= tol * *sum / g.len() as f64 =>
            {
                *sum += c.1.freq_hz;
                g.push(c);
            }
            _ => groups.push((c.1.freq_hz, vec![c])),
        }
    }
    groups
        .into_iter()
        .filter_map(|(_, g)| {
            let mut orders: Vec<usize> = g.iter().map(|x| x.0).collect();
            orders.sort_unstable();
            orders.dedup();
            g.iter().max_by_key(|x| x.0).map(|x| Cluster {
                orders: orders.len(),
                pole: x.1.clone(),
            })
        })
        .collect()
}

/// For each approximate frequency, among the clusters of fully stable, positively damped poles
/// within `window` (relative), the one found at the most orders (the nearest on a tie): its
/// member of the highest order.
pub fn select_near(
    diagram: &StabilizationDiagram,
    approx_hz: &[f64],
    window: f64,
) -> Result<Vec<Pole>> {
    let mut out = Vec::with_capacity(approx_hz.len());
    for &f in approx_hz {
        if !(f > 0.0) || !f.is_finite() {
            return Err(ModalError::InvalidSetting {
                field: "approximate frequency",
                value: f.to_string(),
                reason: "give positive frequencies in Hz".into(),
            });
        }
        let best = clusters(diagram, |p| (p.freq_hz - f).abs() <= window * f)
            .into_iter()
            .max_by(|a, b| {
                a.orders.cmp(&b.orders).then(
                    (b.pole.freq_hz - f)
                        .abs()
                        .total_cmp(&(a.pole.freq_hz - f).abs()),
                )
            });
        match best {
            Some(c) => out.push(c.pole),
            None => {
                return Err(ModalError::NoPoleNear {
                    freq_hz: f,
                    window_pct: window * 100.0,
                })
            }
        }
    }
    Ok(out)
}
