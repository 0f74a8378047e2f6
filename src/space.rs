//! Small dense algebra that does not depend on the space dimension `D` (2 or 3): determinants and
//! cofactor matrices without inversion, and the lift of an in-plane deformation gradient to 3 x 3.

use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector2};

/// The cofactor matrix `cof A = det(A) A^-T` of a 2 x 2 or 3 x 3 matrix, defined also for singular `A`.
#[inline]
pub fn cofactor<const D: usize>(a: &SMatrix<f64, D, D>) -> SMatrix<f64, D, D> {
    match D {
        2 => SMatrix::from_fn(|i, j| {
            let sign = if (i + j) % 2 == 0 { 1.0 } else { -1.0 };
            sign * a[(1 - i, 1 - j)]
        }),
        3 => SMatrix::from_fn(|i, j| {
            let (i1, i2, j1, j2) = ((i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3);
            a[(i1, j1)] * a[(i2, j2)] - a[(i1, j2)] * a[(i2, j1)]
        }),
        _ => panic!("cofactor: dimension {D} is not 2 or 3"),
    }
}

/// `det A` of a 2 x 2 or 3 x 3 matrix (Laplace expansion along the first column).
#[inline]
pub fn det<const D: usize>(a: &SMatrix<f64, D, D>) -> f64 {
    a.column(0).dot(&cofactor(a).column(0))
}

/// The 3 x 3 deformation gradient of a `D`-dimensional one: itself in 3D; in 2D (plane strain) the
/// in-plane block with `F_33 = 1` and `F_13 = F_23 = F_31 = F_32 = 0`.
#[inline]
pub fn lift3<const D: usize>(f: &SMatrix<f64, D, D>) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| {
        if i < D && j < D {
            f[(i, j)]
        } else if i == j {
            1.0
        } else {
            0.0
        }
    })
}

/// The in-plane (x, y) part of a `D`-vector: the plane of the loading devices and their contact.
#[inline]
pub fn xy<const D: usize>(v: &SVector<f64, D>) -> Vector2<f64> {
    Vector2::new(v[0], v[1])
}

/// The `D`-vector with in-plane part `v` and zero z component (3D).
#[inline]
pub fn from_xy<const D: usize>(v: Vector2<f64>) -> SVector<f64, D> {
    SVector::from_fn(|d, _| if d < 2 { v[d] } else { 0.0 })
}

/// The rotation by `theta` (rad, counter-clockwise) in the x-y plane, about the z axis in 3D (the axis of
/// the loading pins of plate specimens).
#[inline]
pub fn rotation_xy<const D: usize>(theta: f64) -> SMatrix<f64, D, D> {
    let (s, c) = theta.sin_cos();
    SMatrix::from_fn(|i, j| match (i, j) {
        (0, 0) | (1, 1) => c,
        (0, 1) => -s,
        (1, 0) => s,
        _ if i == j => 1.0,
        _ => 0.0,
    })
}

/// The frame of a set-up rotated inside the axis-aligned background grid (`[grid] rotation`): the
/// specimen frame turned by `theta` counter-clockwise about the out-of-plane axis through the origin.
/// A vector `v` of the specimen is `R(theta) v` on the grid; results are reported back in the specimen's
/// frame with `R(theta)^T`. Theta = 0 is the identity, exactly (no arithmetic is done).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Theta (degrees).
    degrees: f64,
    /// `cos theta`, `sin theta`; `None`: theta = 0.
    turn: Option<(f64, f64)>,
}

impl Frame {
    /// The specimen on the grid's axes.
    pub const IDENTITY: Frame = Frame {
        degrees: 0.0,
        turn: None,
    };

    /// The frame turned by `degrees` (counter-clockwise).
    pub fn from_degrees(degrees: f64) -> Self {
        if degrees == 0.0 {
            return Self::IDENTITY;
        }
        let (s, c) = degrees.to_radians().sin_cos();
        Self {
            degrees,
            turn: Some((c, s)),
        }
    }

    /// Theta (degrees); `None` for theta = 0.
    pub fn degrees(&self) -> Option<f64> {
        self.turn.map(|_| self.degrees)
    }

    /// True for theta = 0.
    pub fn is_identity(&self) -> bool {
        self.turn.is_none()
    }

    /// `R(theta)` (the identity for theta = 0).
    pub fn matrix(&self) -> Matrix2<f64> {
        match self.turn {
            None => Matrix2::identity(),
            Some((c, s)) => Matrix2::new(c, -s, s, c),
        }
    }

    /// A vector (or point, mm) of the specimen on the grid: `R v`.
    pub fn to_grid(&self, v: Vector2<f64>) -> Vector2<f64> {
        match self.turn {
            None => v,
            Some(_) => self.matrix() * v,
        }
    }

    /// A vector (or point, mm) on the grid in the specimen's frame: `R^T v`.
    pub fn to_specimen(&self, v: Vector2<f64>) -> Vector2<f64> {
        match self.turn {
            None => v,
            Some(_) => self.matrix().transpose() * v,
        }
    }

    /// The in-plane (first two) components of `v` turned back into the specimen's frame (`R^T`); other
    /// components (z) are kept.
    pub fn components_to_specimen(&self, v: &mut [f64]) {
        if let (Some(_), [x, y, ..]) = (self.turn, &mut *v) {
            let w = self.to_specimen(Vector2::new(*x, *y));
            (*x, *y) = (w.x, w.y);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    #[test]
    fn cofactor_is_det_times_inverse_transpose() {
        let a2 = Matrix2::new(1.6, 0.4, -0.3, 0.8);
        let a3 = Matrix3::new(1.2, 0.3, -0.1, 0.2, 0.9, 0.4, -0.5, 0.1, 1.4);
        assert!((det(&a2) - a2.determinant()).abs() < 1e-15);
        assert!((det(&a3) - a3.determinant()).abs() < 1e-14);
        let inv_t2 = a2.try_inverse().unwrap().transpose() * a2.determinant();
        let inv_t3 = a3.try_inverse().unwrap().transpose() * a3.determinant();
        assert!((cofactor(&a2) - inv_t2).norm() < 1e-14);
        assert!((cofactor(&a3) - inv_t3).norm() < 1e-14);
        assert_eq!(lift3(&a2)[(2, 2)], 1.0);
        assert_eq!(lift3(&a2)[(0, 1)], 0.4);
        assert_eq!(lift3(&a3), a3);
    }

    #[test]
    fn frame_turns_counter_clockwise_and_back() {
        let f = Frame::from_degrees(30.0);
        let x = Vector2::new(1.0, 0.0);
        let g = f.to_grid(x);
        assert!((g - Vector2::new(0.75_f64.sqrt(), 0.5)).norm() < 1e-15);
        assert!((f.to_specimen(g) - x).norm() < 1e-15);
        let mut v = [g.x, g.y, 7.0];
        f.components_to_specimen(&mut v);
        assert!((v[0] - 1.0).abs() < 1e-15 && v[1].abs() < 1e-15 && v[2] == 7.0);
        let id = Frame::from_degrees(0.0);
        assert!(id.is_identity() && !f.is_identity());
        assert_eq!(id.degrees(), None);
        assert_eq!(f.degrees(), Some(30.0));
        let y = Vector2::new(-0.3, 1e300);
        assert_eq!(id.to_grid(y), y);
        assert_eq!(id.to_specimen(y), y);
    }
}
