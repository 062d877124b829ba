//! The reduced camera system S·δc = b: its block structure, and its solution with faer's dense
//! Cholesky (small systems) or sparse supernodal Cholesky whose symbolic analysis is computed
//! once and reused across Levenberg–Marquardt iterations (large systems). Both run sequentially
//! inside faer (`Par::Seq`), so results do not depend on the thread count.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::sparse::linalg::cholesky::{
    SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, Mat, Par, Side};
use nalgebra::{SMatrix, SVector};

/// The upper block pattern of S: for camera row `i`, the cameras `j ≥ i` that share a point
/// with it (always including `i`), ascending.
#[derive(Debug, Clone)]
pub(crate) struct BlockPattern {
    /// `row_offsets[i]..row_offsets[i + 1]` indexes `cols` for camera row `i`.
    pub row_offsets: Vec<usize>,
    /// Column cameras of each block, ascending within a row; the first of each row is `i`.
    pub cols: Vec<usize>,
}

impl BlockPattern {
    /// The index (into the row's blocks) of block (i, j), if it is in the pattern.
    pub fn find(&self, i: usize, j: usize) -> Option<usize> {
        let row = &self.cols[self.row_offsets[i]..self.row_offsets[i + 1]];
        row.binary_search(&j).ok()
    }
}

/// Which factorisation solves the reduced camera system.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LinearSolverKind {
    /// Dense Cholesky (faer `llt`) of the full reduced matrix.
    DenseCholesky,
    /// Sparse supernodal Cholesky (faer) with AMD ordering, symbolic analysis reused.
    SparseCholesky,
}

/// A solver for reduced camera systems with a fixed block pattern.
pub(crate) enum ReducedSolver {
    Dense {
        n: usize,
    },
    Sparse {
        n: usize,
        symbolic_matrix: SymbolicSparseColMat<usize>,
        factor: Box<SymbolicCholesky<usize>>,
    },
}

/// Why the reduced system could not be solved: it is not numerically positive definite (the LM
/// loop then raises the damping) or faer failed for another reason.
#[derive(Debug, Clone)]
pub(crate) struct LinearSolveFailure(pub String);

impl ReducedSolver {
    /// Prepares a solver for `num_cameras` cameras with `C` unknowns each. Uses the sparse path
    /// when the system has more than `dense_max_unknowns` unknowns.
    pub fn new<const C: usize>(
        pattern: &BlockPattern,
        num_cameras: usize,
        dense_max_unknowns: usize,
    ) -> Result<Self, LinearSolveFailure> {
        let n = C * num_cameras;
        if n <= dense_max_unknowns {
            return Ok(Self::Dense { n });
        }
        // Lower-triangle CSC pattern: column (i, a) holds rows (i, b ≥ a), then (j, 0..C) for
        // every j > i in the block row of i.
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0usize);
        for i in 0..num_cameras {
            let row = &pattern.cols[pattern.row_offsets[i]..pattern.row_offsets[i + 1]];
            for a in 0..C {
                for b in a..C {
                    row_idx.push(i * C + b);
                }
                for &j in &row[1..] {
                    for b in 0..C {
                        row_idx.push(j * C + b);
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        let symbolic_matrix = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let factor = factorize_symbolic_cholesky(
            symbolic_matrix.as_ref(),
            Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|e| LinearSolveFailure(format!("symbolic Cholesky analysis failed: {e:?}")))?;
        Ok(Self::Sparse {
            n,
            symbolic_matrix,
            factor: Box::new(factor),
        })
    }

    /// The kind of factorisation in use.
    pub fn kind(&self) -> LinearSolverKind {
        match self {
            Self::Dense { .. } => LinearSolverKind::DenseCholesky,
            Self::Sparse { .. } => LinearSolverKind::SparseCholesky,
        }
    }

    /// Solves S·x = rhs, where S is given by its upper blocks `rows[i][k]` = S(i, cols[k]) in
    /// `pattern` order. Returns x.
    pub fn solve<const C: usize>(
        &self,
        pattern: &BlockPattern,
        rows: &[Vec<SMatrix<f64, C, C>>],
        rhs: &[SVector<f64, C>],
    ) -> Result<Vec<SVector<f64, C>>, LinearSolveFailure> {
        let num_cameras = rhs.len();
        let mut b = Mat::<f64>::zeros(C * num_cameras, 1);
        for (i, r) in rhs.iter().enumerate() {
            for a in 0..C {
                b[(i * C + a, 0)] = r[a];
            }
        }
        match self {
            Self::Dense { n } => {
                let mut s = Mat::<f64>::zeros(*n, *n);
                for (i, row) in rows.iter().enumerate() {
                    let cols = &pattern.cols[pattern.row_offsets[i]..pattern.row_offsets[i + 1]];
                    for (block, &j) in row.iter().zip(cols) {
                        // Lower triangle: entry (j·C + b, i·C + a) = S(i·C + a, j·C + b).
                        for a in 0..C {
                            for bb in 0..C {
                                if j > i || bb >= a {
                                    s[(j * C + bb, i * C + a)] = block[(a, bb)];
                                }
                            }
                        }
                    }
                }
                let mut buf = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
                    *n,
                    Par::Seq,
                    Default::default(),
                ));
                llt::factor::cholesky_in_place(
                    s.as_mut(),
                    Default::default(),
                    Par::Seq,
                    MemStack::new(&mut buf),
                    Default::default(),
                )
                .map_err(|e| LinearSolveFailure(format!("dense Cholesky failed: {e:?}")))?;
                let mut sbuf =
                    MemBuffer::new(llt::solve::solve_in_place_scratch::<f64>(*n, 1, Par::Seq));
                llt::solve::solve_in_place(
                    s.as_ref(),
                    b.as_mut(),
                    Par::Seq,
                    MemStack::new(&mut sbuf),
                );
            }
            Self::Sparse {
                n,
                symbolic_matrix,
                factor,
            } => {
                let mut values = Vec::with_capacity(symbolic_matrix.row_idx().len());
                for row in rows {
                    for a in 0..C {
                        for bb in a..C {
                            values.push(row[0][(bb, a)]);
                        }
                        for block in &row[1..] {
                            for bb in 0..C {
                                values.push(block[(a, bb)]);
                            }
                        }
                    }
                }
                let matrix = SparseColMatRef::new(symbolic_matrix.as_ref(), &values);
                let mut l_values = vec![0.0f64; factor.len_val()];
                let mut buf = MemBuffer::new(
                    factor.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
                );
                let llt_ref = factor
                    .factorize_numeric_llt::<f64>(
                        &mut l_values,
                        matrix,
                        Side::Lower,
                        Default::default(),
                        Par::Seq,
                        MemStack::new(&mut buf),
                        Default::default(),
                    )
                    .map_err(|e| LinearSolveFailure(format!("sparse Cholesky failed: {e:?}")))?;
                let mut sbuf = MemBuffer::new(factor.solve_in_place_scratch::<f64>(1, Par::Seq));
                llt_ref.solve_in_place_with_conj(
                    Conj::No,
                    b.as_mut(),
                    Par::Seq,
                    MemStack::new(&mut sbuf),
                );
                debug_assert_eq!(b.nrows(), *n);
            }
        }
        Ok((0..num_cameras)
            .map(|i| SVector::<f64, C>::from_fn(|a, _| b[(i * C + a, 0)]))
            .collect())
    }
}
