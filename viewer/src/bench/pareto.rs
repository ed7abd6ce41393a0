//! The Pareto front of run time against error: a point is on the front when no other point is
//! at least as fast and at least as accurate, and strictly better in one of the two.

/// Indices of the points `(time, quality)` on the Pareto front (lower time and higher quality
/// are better), in input order. Points with a non-finite time are never on the front; an
/// infinite quality (an exact image) is the best possible.
pub fn front(points: &[(f64, f64)]) -> Vec<usize> {
    (0..points.len())
        .filter(|&i| {
            let (t, q) = points[i];
            t.is_finite()
                && !q.is_nan()
                && !points.iter().enumerate().any(|(j, &(tj, qj))| {
                    j != i && tj.is_finite() && tj <= t && qj >= q && (tj < t || qj > q)
                })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dominated_points_are_off_the_front() {
        let p = [
            (1.0, 30.0),
            (2.0, 40.0),
            (2.0, 35.0),
            (3.0, 39.0),
            (0.5, 20.0),
        ];
        assert_eq!(front(&p), vec![0, 1, 4]);
        // Ties are both on the front.
        assert_eq!(front(&[(1.0, 1.0), (1.0, 1.0)]), vec![0, 1]);
        assert_eq!(front(&[(f64::NAN, 50.0), (1.0, 1.0)]), vec![1]);
        assert_eq!(front(&[(2.0, f64::INFINITY), (1.0, 1.0)]), vec![0, 1]);
    }
}
