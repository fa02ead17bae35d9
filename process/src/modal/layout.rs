//! Test layouts: which FRFs a measurement holds, and how they are arranged for the estimator.
//!
//! An impact or shaker test measures FRFs `H(response ← reference)` between channels (node and
//! direction). The common layouts:
//!
//! - **roving hammer**: one or a few fixed accelerometers, the hammer roved over many points
//!   (few responses × many references);
//! - **roving accelerometer**: one or a few fixed excitation points (hammer or shaker), the
//!   accelerometer roved (many responses × few references);
//! - **multi-reference** (MIMO shaker tests, or hammer and sensors at every point): both sides
//!   hold several channels;
//! - **mixed**: FRFs of both kinds in one set (for example a roving-hammer row and a
//!   roving-accelerometer column through the same driving point), which form a full grid only
//!   once some FRFs are read in the reciprocal direction.
//!
//! The poly-reference estimator carries a matrix polynomial as wide as the reference side and a
//! numerator per output; its denominator is only identifiable when the outputs outnumber (or
//! match) the references. So the FRFs are arranged as **points × fixed channels**: the side with
//! fewer channels carries the polynomial (the estimator's references) and the side that holds the
//! points carries the mode shapes (the estimator's outputs). When the fixed channels are the
//! file's responses (a roving hammer), every FRF is read transposed, which Maxwell-Betti
//! reciprocity (`H_pq = H_qp` for a linear, passive structure measured at the same degrees of
//! freedom) makes the FRF of a force at the fixed channel and a response at the point.
//!
//! Channels are compared literally (node and signed direction): reciprocity fills a cell only from
//! an FRF whose response and reference are exactly that cell's reference and response.

use std::collections::{BTreeMap, BTreeSet};

use super::{FrfKind, ModalData, ModalError, Result};
use crate::C64;

/// A measurement channel: node and direction (as UFF numbers them, the sign included).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Channel {
    /// Node number.
    pub node: i64,
    /// Direction (1..3 translations, 4..6 rotations, negative for the opposite sense).
    pub dir: i64,
}

impl std::fmt::Display for Channel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.node, self.dir)
    }
}

/// One measured FRF with its channels and where it came from (for error messages).
#[derive(Debug, Clone)]
pub struct MeasuredFrf {
    /// Response channel (accelerometer, displacement probe …).
    pub response: Channel,
    /// Reference channel (hammer or shaker force).
    pub reference: Channel,
    /// Values on the set's common lines.
    pub h: Vec<C64>,
    /// Where it came from, e.g. "dataset 7".
    pub source: String,
}

/// The recognised layout of a set of FRFs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LayoutKind {
    /// One response, one reference.
    Single,
    /// Few fixed responses, the reference (hammer) roved over the points.
    RovingHammer,
    /// Few fixed references, the response (accelerometer) roved over the points.
    RovingAccelerometer,
    /// Several references and several responses on a full grid.
    MultiReference,
    /// A grid completed by reading some FRFs in the reciprocal direction.
    Mixed,
}

impl LayoutKind {
    /// Name for tables and JSON.
    pub fn name(self) -> &'static str {
        match self {
            LayoutKind::Single => "single FRF",
            LayoutKind::RovingHammer => "roving hammer",
            LayoutKind::RovingAccelerometer => "roving accelerometer",
            LayoutKind::MultiReference => "multi-reference",
            LayoutKind::Mixed => "mixed",
        }
    }
}

/// At most this many fixed channels make a "roving" layout; beyond, both sides are several and
/// the set is a multi-reference test.
pub const FEW_CHANNELS: usize = 3;

/// How the FRFs were arranged for the estimator: `ModalData`'s outputs are [`Layout::points`],
/// its references [`Layout::fixed`].
#[derive(Debug, Clone)]
pub struct Layout {
    /// What the set is.
    pub kind: LayoutKind,
    /// The channels the mode shapes are given over (the estimator's outputs).
    pub points: Vec<Channel>,
    /// The channels that carry the polynomial (the estimator's references).
    pub fixed: Vec<Channel>,
    /// The fixed channels are the file's responses: every FRF is read transposed (reciprocity).
    pub transposed: bool,
    /// Cells of the grid filled from the FRF measured in the other direction (reciprocity); all
    /// of them when `transposed`.
    pub reciprocal: usize,
    /// Fixed channels that are also points: the driving-point FRFs, which scale the shapes.
    pub driving_points: Vec<Channel>,
}

impl Layout {
    /// One sentence for the user: the layout and which side carries what.
    pub fn describe(&self) -> String {
        let side = if self.transposed {
            "the fixed responses carry the polynomial: FRFs transposed by reciprocity (H_pq = H_qp)"
                .to_string()
        } else if self.reciprocal > 0 {
            format!(
                "the fixed channels carry the polynomial; {} FRFs read transposed by reciprocity (H_pq = H_qp)",
                self.reciprocal
            )
        } else {
            "the references carry the polynomial".to_string()
        };
        format!(
            "layout: {}, {} points × {} fixed channels; {side}; shapes over the points",
            self.kind.name(),
            self.points.len(),
            self.fixed.len()
        )
    }
}

/// Arranges measured FRFs (all on `freqs_hz`) as points × fixed channels: recognises the layout,
/// refuses a pair measured twice and a grid with holes (naming the missing FRFs).
pub fn arrange(
    frfs: Vec<MeasuredFrf>,
    freqs_hz: Vec<f64>,
    kind: FrfKind,
) -> Result<(ModalData, Layout)> {
    let mut cells: BTreeMap<(Channel, Channel), MeasuredFrf> = BTreeMap::new();
    let mut responses: Vec<Channel> = Vec::new();
    let mut references: Vec<Channel> = Vec::new();
    for f in frfs {
        if !responses.contains(&f.response) {
            responses.push(f.response);
        }
        if !references.contains(&f.reference) {
            references.push(f.reference);
        }
        let key = (f.response, f.reference);
        if let Some(first) = cells.get(&key) {
            return Err(ModalError::DuplicateFrf {
                response: f.response.to_string(),
                reference: f.reference.to_string(),
                first: first.source.clone(),
                second: f.source,
            });
        }
        cells.insert(key, f);
    }
    if cells.is_empty() {
        return Err(ModalError::Layout {
            reason: "no FRF in the set".into(),
        });
    }
    let full = cells.len() == responses.len() * references.len();
    let (points, fixed, transposed) = if full {
        if responses.len() >= references.len() {
            (responses.clone(), references.clone(), false)
        } else {
            (references.clone(), responses.clone(), true)
        }
    } else {
        let fixed = cover(&cells, &references);
        let mut points: Vec<Channel> = Vec::new();
        for &(r, q) in cells.keys() {
            let p = if fixed.contains(&q) { r } else { q };
            if !points.contains(&p) {
                points.push(p);
            }
        }
        // Keep the file's order of appearance where it has one.
        points.sort_by_key(|c| {
            responses
                .iter()
                .chain(&references)
                .position(|x| x == c)
                .unwrap_or(usize::MAX)
        });
        (points, fixed, false)
    };

    let lines = freqs_hz.len();
    let mut h = Vec::with_capacity(points.len() * fixed.len() * lines);
    let mut missing = Vec::new();
    let mut reciprocal = 0;
    for &p in &points {
        for &q in &fixed {
            let direct = if transposed { None } else { cells.get(&(p, q)) };
            match direct.or_else(|| cells.get(&(q, p))) {
                Some(f) => {
                    if direct.is_none() {
                        reciprocal += 1;
                    }
                    if f.h.len() != lines {
                        return Err(ModalError::Layout {
                            reason: format!(
                                "{} holds {} lines, the set {lines}: all FRFs must share their lines",
                                f.source,
                                f.h.len()
                            ),
                        });
                    }
                    h.extend_from_slice(&f.h);
                }
                // Named as the file would hold it: response ← reference.
                None if responses.contains(&q) && references.contains(&p) => {
                    missing.push(format!("{q} ← {p}"))
                }
                None => missing.push(format!("{p} ← {q}")),
            }
        }
    }
    if !missing.is_empty() {
        return Err(ModalError::MissingFrfs {
            points: points.len(),
            fixed: fixed.iter().map(|c| c.to_string()).collect(),
            count: missing.len(),
            missing: missing.into_iter().take(12).collect(),
        });
    }
    let kind_of = if points.len() == 1 && fixed.len() == 1 {
        LayoutKind::Single
    } else if reciprocal > 0 && !transposed {
        LayoutKind::Mixed
    } else if fixed.len() <= FEW_CHANNELS && points.len() > fixed.len() {
        if transposed {
            LayoutKind::RovingHammer
        } else {
            LayoutKind::RovingAccelerometer
        }
    } else {
        LayoutKind::MultiReference
    };
    let driving_points = fixed
        .iter()
        .copied()
        .filter(|q| points.contains(q))
        .collect();
    let data = ModalData::new(freqs_hz, points.len(), fixed.len(), h, kind)?;
    Ok((
        data,
        Layout {
            kind: kind_of,
            points,
            fixed,
            transposed,
            reciprocal,
            driving_points,
        },
    ))
}

/// The fewest channels (greedy) such that every FRF has one of its two channels among them: the
/// fixed side of an incomplete grid. Ties go to the file's references, so a set needs no
/// reciprocity where it can do without.
fn cover(
    cells: &BTreeMap<(Channel, Channel), MeasuredFrf>,
    references: &[Channel],
) -> Vec<Channel> {
    let mut left: BTreeSet<(Channel, Channel)> = cells.keys().copied().collect();
    let mut fixed = Vec::new();
    while !left.is_empty() {
        let mut count: BTreeMap<Channel, usize> = BTreeMap::new();
        for &(r, q) in &left {
            *count.entry(r).or_default() += 1;
            if q != r {
                *count.entry(q).or_default() += 1;
            }
        }
        let Some((&best, _)) = count
            .iter()
            .max_by_key(|(c, n)| (**n, references.contains(c), std::cmp::Reverse(**c)))
        else {
            break;
        };
        fixed.push(best);
        left.retain(|&(r, q)| r != best && q != best);
    }
    fixed
}

/// Mode shapes scaled to unit modal mass from a driving point `q` (fixed channel index `fixed`,
/// point index `point`): with the receptance residue `A_pq = ψ_p ψ_q / (2iω_d)` of a lightly
/// damped mode, `ψ_q = √(2iω_d A_qq)` and `ψ_p = 2iω_d A_pq / ψ_q` (1/√kg for FRFs in SI).
pub fn mass_normalized(
    residues: &[C64],
    references: usize,
    fixed: usize,
    point: usize,
    lambda: C64,
) -> Vec<C64> {
    let outputs = residues.len() / references.max(1);
    let two_i_wd = C64::new(0.0, 2.0 * lambda.im);
    let psi_q = (two_i_wd * residues[point * references + fixed]).sqrt();
    if psi_q.norm() == 0.0 {
        return vec![C64::new(0.0, 0.0); outputs];
    }
    (0..outputs)
        .map(|p| two_i_wd * residues[p * references + fixed] / psi_q)
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn ch(node: i64) -> Channel {
        Channel { node, dir: 3 }
    }

    fn frf(r: i64, q: i64) -> MeasuredFrf {
        MeasuredFrf {
            response: ch(r),
            reference: ch(q),
            h: vec![C64::new(r as f64, q as f64); 4],
            source: format!("H{r},{q}"),
        }
    }

    fn freqs() -> Vec<f64> {
        vec![1.0, 2.0, 3.0, 4.0]
    }

    #[test]
    fn roving_hammer_is_transposed() {
        let set = (11..=15).map(|q| frf(1, q)).collect();
        let (data, lay) = arrange(set, freqs(), FrfKind::Accelerance).unwrap();
        assert_eq!(lay.kind, LayoutKind::RovingHammer);
        assert!(lay.transposed);
        assert_eq!((data.outputs, data.references), (5, 1));
        assert_eq!(lay.points, (11..=15).map(ch).collect::<Vec<_>>());
        // Output 2 is the point 13: the FRF H(1 ← 13).
        assert_eq!(data.frf(2, 0)[0], C64::new(1.0, 13.0));
        assert_eq!(lay.reciprocal, 5);
    }

    #[test]
    fn roving_accelerometer_and_mimo_keep_their_direction() {
        let set = (1..=6).map(|r| frf(r, 1)).collect();
        let (data, lay) = arrange(set, freqs(), FrfKind::Accelerance).unwrap();
        assert_eq!(lay.kind, LayoutKind::RovingAccelerometer);
        assert!(!lay.transposed && lay.reciprocal == 0);
        assert_eq!((data.outputs, data.references), (6, 1));
        assert_eq!(lay.driving_points, vec![ch(1)]);

        let set = (1..=7)
            .flat_map(|r| (11..=16).map(move |q| frf(r, q)))
            .collect();
        let (data, lay) = arrange(set, freqs(), FrfKind::Accelerance).unwrap();
        assert_eq!(lay.kind, LayoutKind::MultiReference);
        assert_eq!((data.outputs, data.references), (7, 6));
        assert!(lay.driving_points.is_empty());
    }

    #[test]
    fn a_cross_is_completed_by_reciprocity() {
        // A roving-hammer row (response 1) and a roving-accelerometer column (reference 1).
        let mut set: Vec<MeasuredFrf> = (1..=4).map(|r| frf(r, 1)).collect();
        set.extend((5..=7).map(|q| frf(1, q)));
        let (data, lay) = arrange(set, freqs(), FrfKind::Accelerance).unwrap();
        assert_eq!(lay.kind, LayoutKind::Mixed);
        assert_eq!(lay.fixed, vec![ch(1)]);
        assert_eq!(data.outputs, 7);
        assert_eq!(lay.reciprocal, 3);
        assert_eq!(data.frf(6, 0)[0], C64::new(1.0, 7.0));
    }

    #[test]
    fn holes_and_duplicates_are_named() {
        let mut set: Vec<MeasuredFrf> = (1..=3)
            .flat_map(|r| (11..=12).map(move |q| frf(r, q)))
            .collect();
        set.retain(|f| !(f.response == ch(2) && f.reference == ch(12)));
        let err = arrange(set, freqs(), FrfKind::Accelerance)
            .unwrap_err()
            .to_string();
        assert!(err.contains("2:3 ← 12:3") && err.contains("1 of"), "{err}");

        let set = vec![frf(1, 11), frf(2, 11), frf(1, 11)];
        let err = arrange(set, freqs(), FrfKind::Accelerance)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("H1,11") && err.contains("1:3") && err.contains("11:3"),
            "{err}"
        );
    }

    #[test]
    fn unit_modal_mass_from_the_driving_point() {
        // Two points, fixed channel = point 0; ψ = (0.5, -0.25) 1/√kg, ω_d = 100 rad/s.
        let lambda = C64::new(-1.0, 100.0);
        let psi = [0.5, -0.25];
        let res: Vec<C64> = psi
            .iter()
            .map(|p| C64::new(p * psi[0], 0.0) / C64::new(0.0, 200.0))
            .collect();
        let s = mass_normalized(&res, 1, 0, 0, lambda);
        assert!((s[0] - C64::new(0.5, 0.0)).norm() < 1e-12, "{s:?}");
        assert!((s[1] - C64::new(-0.25, 0.0)).norm() < 1e-12, "{s:?}");
    }
}
