//! Small dense square matrices for the layer operators: products and
//! solves by LU decomposition with partial pivoting (Golub and Van Loan,
//! Matrix Computations, 4th ed., algorithm 3.4.1). The operators are at most
//! a few dozen streams on a side, so nothing here needs blocking or BLAS.

/// An `n` x `n` matrix, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Mat {
    pub n: usize,
    pub a: Vec<f64>,
}

impl Mat {
    pub fn zeros(n: usize) -> Mat {
        Mat { n, a: vec![0.0; n * n] }
    }

    pub fn identity(n: usize) -> Mat {
        let mut m = Mat::zeros(n);
        for i in 0..n {
            m.a[i * n + i] = 1.0;
        }
        m
    }

    #[inline]
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.a[i * self.n + j]
    }

    #[inline]
    pub fn set(&mut self, i: usize, j: usize, v: f64) {
        self.a[i * self.n + j] = v;
    }

    pub fn mul(&self, b: &Mat) -> Mat {
        let n = self.n;
        let mut c = Mat::zeros(n);
        for i in 0..n {
            for k in 0..n {
                let x = self.a[i * n + k];
                if x == 0.0 {
                    continue;
                }
                let (row, brow) = (&mut c.a[i * n..(i + 1) * n], &b.a[k * n..(k + 1) * n]);
                for (c, b) in row.iter_mut().zip(brow) {
                    *c += x * b;
                }
            }
        }
        c
    }

    pub fn mul_vec(&self, v: &[f64]) -> Vec<f64> {
        let n = self.n;
        (0..n).map(|i| self.a[i * n..(i + 1) * n].iter().zip(v).map(|(a, b)| a * b).sum()).collect()
    }

    /// `self + s b`.
    pub fn add_scaled(&self, b: &Mat, s: f64) -> Mat {
        Mat { n: self.n, a: self.a.iter().zip(&b.a).map(|(x, y)| x + s * y).collect() }
    }

    /// `I - self`.
    pub fn one_minus(&self) -> Mat {
        Mat::identity(self.n).add_scaled(self, -1.0)
    }

    /// The LU factors of `self`, or `None` if it is singular to working
    /// precision.
    pub fn lu(&self) -> Option<Lu> {
        let n = self.n;
        let mut a = self.a.clone();
        let mut perm: Vec<usize> = (0..n).collect();
        for k in 0..n {
            let p = (k..n).max_by(|&i, &j| a[i * n + k].abs().total_cmp(&a[j * n + k].abs()))?;
            if a[p * n + k] == 0.0 || !a[p * n + k].is_finite() {
                return None;
            }
            if p != k {
                for j in 0..n {
                    a.swap(k * n + j, p * n + j);
                }
                perm.swap(k, p);
            }
            let pivot = a[k * n + k];
            for i in k + 1..n {
                let f = a[i * n + k] / pivot;
                a[i * n + k] = f;
                if f != 0.0 {
                    for j in k + 1..n {
                        a[i * n + j] -= f * a[k * n + j];
                    }
                }
            }
        }
        Some(Lu { n, a, perm })
    }
}

/// `P A = L U`, L unit lower triangular, stored together.
#[derive(Debug, Clone)]
pub struct Lu {
    n: usize,
    a: Vec<f64>,
    perm: Vec<usize>,
}

impl Lu {
    /// x with A x = b.
    pub fn solve_vec(&self, b: &[f64]) -> Vec<f64> {
        let n = self.n;
        let mut x: Vec<f64> = self.perm.iter().map(|&p| b[p]).collect();
        for i in 0..n {
            let s: f64 = (0..i).map(|j| self.a[i * n + j] * x[j]).sum();
            x[i] -= s;
        }
        for i in (0..n).rev() {
            let s: f64 = (i + 1..n).map(|j| self.a[i * n + j] * x[j]).sum();
            x[i] = (x[i] - s) / self.a[i * n + i];
        }
        x
    }

    /// X with A X = B.
    pub fn solve(&self, b: &Mat) -> Mat {
        let n = self.n;
        let mut x = Mat::zeros(n);
        let mut col = vec![0.0; n];
        for j in 0..n {
            for i in 0..n {
                col[i] = b.a[i * n + j];
            }
            for (i, v) in self.solve_vec(&col).into_iter().enumerate() {
                x.a[i * n + j] = v;
            }
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_solve_inverts_a_product() {
        let n = 5;
        let mut a = Mat::zeros(n);
        for i in 0..n {
            for j in 0..n {
                a.set(i, j, ((i * 7 + j * 3) % 11) as f64 - 4.0 + if i == j { 9.0 } else { 0.0 });
            }
        }
        let mut b = Mat::zeros(n);
        for (k, v) in b.a.iter_mut().enumerate() {
            *v = (k as f64 * 0.37).sin();
        }
        let x = a.lu().unwrap().solve(&b);
        let back = a.mul(&x);
        for (p, q) in back.a.iter().zip(&b.a) {
            assert!((p - q).abs() < 1e-12, "{p} {q}");
        }
        assert!(Mat::zeros(3).lu().is_none());
    }
}
