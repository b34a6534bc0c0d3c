// Linearised backward Euler on the active set (Baraff & Witkin 1998):
//   (M - T df/dv - T^2 df/dx) dv = T (f + T df/dx v),  v += dv,  x += T v,
// assembled as a row-major CSR matrix in preallocated buffers that Eigen views through
// Eigen::Map, solved by Jacobi-preconditioned conjugate gradient warm-started from the last dv.
// Eigen's own ConjugateGradient was rejected: it allocates its work vectors on every solve.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>

#include "idms/sim/model.h"
#include "idms/sim/tool.h"
#include "idms/sim/workspace.h"
#include "step_internal.h"

namespace idms::internal {
namespace {

using Vec = Eigen::Matrix<Real, Eigen::Dynamic, 1>;
using VecMap = Eigen::Map<Vec>;
using SparseMap = Eigen::Map<const Eigen::SparseMatrix<Real, Eigen::RowMajor, int32_t>>;

void Reserve(ImplicitBuffers& ib, int64_t atoms, int64_t nnz) {
  ib.outer.resize(3 * atoms + 1);
  ib.inner.resize(nnz);
  ib.values.resize(nnz);
  for (std::vector<Real>* v : {&ib.rhs, &ib.dv, &ib.r, &ib.z, &ib.p, &ib.q, &ib.inv_diag}) v->resize(3 * atoms);
  ib.diag_blocks.resize(9 * atoms);
}

// Other endpoint of element e seen from atom a.
inline int32_t Other(const Model& m, int32_t e, int32_t a) {
  const int32_t a0 = m.elem_atoms[2 * e];
  return a0 == a ? m.elem_atoms[2 * e + 1] : a0;
}

// Stiffness block of a spring from a to b (PSD: the compressive geometric term is dropped so
// that the system stays SPD for CG), and its damping block b s^ s^T.
void SpringBlocks(const Real* pa, const Real* pb, double k, double leq, double damping, Real K[9], Real B[9]) {
  const Real sv[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
  const Real l = std::sqrt(sv[0] * sv[0] + sv[1] * sv[1] + sv[2] * sv[2]);
  if (!(l > kMinLength)) {
    for (int i = 0; i < 9; ++i) K[i] = (i % 4 == 0) ? static_cast<Real>(k) : Real(0), B[i] = 0;
    return;
  }
  const Real n[3] = {sv[0] / l, sv[1] / l, sv[2] / l};
  const Real g = std::max(Real(0), Real(1) - static_cast<Real>(leq) / l);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      const Real nn = n[r] * n[c];
      K[3 * r + c] = static_cast<Real>(k) * ((Real(1) - g) * nn + (r == c ? g : Real(0)));
      B[3 * r + c] = static_cast<Real>(damping) * nn;
    }
  }
}

// Number of matrix entries of slot i's three rows: diagonal block + one per active neighbour.
int32_t RowBlocks(const Model& m, const Workspace& ws, int32_t a) {
  int32_t blocks = 1;
  const int32_t adr = m.atom_elem_adr[a];
  for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) {
    const int32_t e = m.atom_elem[adr + j];
    if (!ws.elem_cut[e] && ws.atom_slot[Other(m, e, a)] >= 0) ++blocks;
  }
  return blocks;
}

// Diagonal blocks before elements: M, air T c m I, tool contact and grasp T^2 K; rhs = T f - T^2 K v.
void PrefillDiagonal(const Model& m, const State& s, Workspace& ws, Real T) {
  ImplicitBuffers& ib = ws.implicit;
  const Real t2 = T * T;
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    const Real diag = static_cast<Real>(m.atom_mass[a] * (1.0 + T * ws.options.air_damping));
    for (int j = 0; j < 9; ++j) ib.diag_blocks[9 * i + j] = (j % 4 == 0) ? diag : Real(0);
    for (int c = 0; c < 3; ++c) ib.rhs[3 * i + c] = T * ws.atom_force[3 * a + c];
  }
  auto add_block = [&](int32_t a, const Real K[9]) {
    const int32_t i = ws.atom_slot[a];
    if (i < 0) return;
    const Real* v = &s.atom_vel[3 * a];
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        ib.diag_blocks[9 * i + 3 * r + c] += t2 * K[3 * r + c];
        ib.rhs[3 * i + r] -= t2 * K[3 * r + c] * v[c];
      }
    }
  };
  for (int32_t t = 0; t < ws.num_tools; ++t) {
    const ActiveTool& at = ws.tools[t];
    if (!IsContactTool(at.kind)) continue;
    for (int32_t j = 0; j < ws.num_candidates; ++j) {
      const int32_t a = ws.candidates[j];
      if (a == at.grasp_atom || ws.atom_slot[a] < 0) continue;
      const Real* p = &s.atom_pos[3 * a];
      const double d[3] = {p[0] - at.pos[0], p[1] - at.pos[1], p[2] - at.pos[2]};
      const ContactForce cf = SphereContact(at.law, at.stiffness, at.radius, ws.options.min_distance_fraction, d);
      if (!cf.touching) continue;
      const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      const double n[3] = {len > 0 ? d[0] / len : 0, len > 0 ? d[1] / len : 0, len > 0 ? d[2] / len : 1};
      Real K[9];
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) K[3 * r + c] = static_cast<Real>(cf.stiffness * n[r] * n[c]);
      }
      add_block(a, K);
    }
    if (at.grasp_atom >= 0) {
      const Real centre[3] = {static_cast<Real>(at.pos[0]), static_cast<Real>(at.pos[1]), static_cast<Real>(at.pos[2])};
      Real K[9], B[9];
      SpringBlocks(&s.atom_pos[3 * at.grasp_atom], centre, at.grasp_k, at.grasp_leq, 0, K, B);
      add_block(at.grasp_atom, K);
    }
    // Friction's tangential spring on each anchor atom, w^2 (k_t + b_t / T) (I - n n^T), as if it
    // stuck (the slipping force's own stiffness is smaller: this errs on the damped side).
    // Rejected: the anchor atoms' coupling blocks w_i w_j (a few entries outside the pattern).
    if (at.friction == FrictionState::kNone || !(at.eval_fn > 0)) continue;
    const double keff = at.k_t + at.b_t / ws.options.dt_s;
    const double* n = at.eval_normal;
    for (int i = 0; i < kAnchorAtoms && at.anchor_atoms[i] >= 0; ++i) {
      Real K[9];
      const double w2 = at.anchor_w[i] * at.anchor_w[i] * keff;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) K[3 * r + c] = static_cast<Real>(w2 * ((r == c ? 1.0 : 0.0) - n[r] * n[c]));
      }
      add_block(at.anchor_atoms[i], K);
    }
  }
}

// Element blocks, row by row (each element is seen from both active endpoints). Returns nnz.
int64_t FillRows(const Model& m, const State& s, Workspace& ws, Real T) {
  ImplicitBuffers& ib = ws.implicit;
  const Real t2 = T * T;
  int64_t nnz = 0;
  for (int32_t i = 0; i < ws.num_active; ++i) {
    const int32_t a = ws.active[i];
    const int32_t row_len = 3 * RowBlocks(m, ws, a);
    for (int r = 0; r < 3; ++r) ib.outer[3 * i + r] = static_cast<int32_t>(nnz + r * row_len);
    Real* D = &ib.diag_blocks[9 * i];
    int32_t block = 1;
    const int32_t adr = m.atom_elem_adr[a];
    for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) {
      const int32_t e = m.atom_elem[adr + j];
      if (ws.elem_cut[e]) continue;
      const int32_t b = Other(m, e, a);
      Real K[9], B[9];
      SpringBlocks(&s.atom_pos[3 * a], &s.atom_pos[3 * b], m.elem_k[e], m.elem_leq[e], m.elem_b[e], K, B);
      const Real* va = &s.atom_vel[3 * a];
      const Real* vb = &s.atom_vel[3 * b];
      const int32_t slot_b = ws.atom_slot[b];
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
          const Real w = T * B[3 * r + c] + t2 * K[3 * r + c];
          D[3 * r + c] += w;
          ib.rhs[3 * i + r] -= t2 * K[3 * r + c] * (va[c] - vb[c]);
          if (slot_b < 0) continue;
          const int64_t at = ib.outer[3 * i + r] + 3 * block + c;
          ib.values[at] = -w;
          ib.inner[at] = 3 * slot_b + c;
        }
      }
      if (slot_b >= 0) ++block;
    }
    // The diagonal block goes first in each row; its diagonal feeds the Jacobi preconditioner.
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        ib.values[ib.outer[3 * i + r] + c] = D[3 * r + c];
        ib.inner[ib.outer[3 * i + r] + c] = 3 * i + c;
      }
      ib.inv_diag[3 * i + r] = Real(1) / D[4 * r];
    }
    nnz += 3 * row_len;
  }
  ib.outer[3 * ws.num_active] = static_cast<int32_t>(nnz);
  return nnz;
}

// Jacobi-preconditioned CG on A dv = rhs from the warm start in ib.dv. Returns iterations.
int32_t SolveCg(Workspace& ws, int32_t rows, int64_t nnz, bool* converged) {
  ImplicitBuffers& ib = ws.implicit;
  const SparseMap A(rows, rows, nnz, ib.outer.data(), ib.inner.data(), ib.values.data());
  VecMap x(ib.dv.data(), rows), b(ib.rhs.data(), rows), r(ib.r.data(), rows), z(ib.z.data(), rows),
      p(ib.p.data(), rows), q(ib.q.data(), rows), inv_diag(ib.inv_diag.data(), rows);
  const Real b_norm2 = b.squaredNorm();
  *converged = true;
  if (!(b_norm2 > 0)) {
    x.setZero();
    return 0;
  }
  const Real tol2 = static_cast<Real>(ws.options.stability.cg_tolerance * ws.options.stability.cg_tolerance) * b_norm2;
  q.noalias() = A * x;
  r = b - q;
  // A warm start from a failed attempt may be non-finite: start from zero instead.
  if (!std::isfinite(r.squaredNorm())) {
    x.setZero();
    r = b;
  }
  z = inv_diag.cwiseProduct(r);
  p = z;
  Real rz = r.dot(z);
  int32_t it = 0;
  for (; it < ws.options.stability.cg_max_iterations; ++it) {
    if (r.squaredNorm() <= tol2) return it;
    q.noalias() = A * p;
    const Real pq = p.dot(q);
    if (!(pq > 0)) break;  // not SPD (cannot happen with the clamped blocks) or non-finite
    const Real alpha = rz / pq;
    x += alpha * p;
    r -= alpha * q;
    z = inv_diag.cwiseProduct(r);
    const Real rz_next = r.dot(z);
    p = z + (rz_next / rz) * p;
    rz = rz_next;
  }
  *converged = r.squaredNorm() <= tol2;
  return it;
}

}  // namespace

void SizeImplicitBuffers(const Model& m, Workspace& ws) {
  int64_t num_free = 0, free_pairs = 0, max_degree = 0;
  for (int32_t a = 0; a < m.num_atoms; ++a) {
    if (m.atom_fixed[a]) continue;
    ++num_free;
    max_degree = std::max<int64_t>(max_degree, m.atom_elem_num[a]);
  }
  for (int32_t e = 0; e < m.num_elems; ++e)
    free_pairs += !m.atom_fixed[m.elem_atoms[2 * e]] && !m.atom_fixed[m.elem_atoms[2 * e + 1]];
  // Full mode: the whole free system. Local mode: a generous window; Step grows it if needed.
  const int64_t atoms = ws.options.full ? num_free : std::min<int64_t>(num_free, 2048);
  const int64_t nnz =
      ws.options.full ? 9 * (num_free + 2 * free_pairs) : 9 * atoms * (1 + std::min<int64_t>(max_degree, 24));
  Reserve(ws.implicit, std::max<int64_t>(atoms, 1), std::max<int64_t>(nnz, 9));
  ws.implicit.atom_dv_guess.assign(3 * static_cast<size_t>(m.num_atoms), Real(0));
}

int32_t ImplicitEulerSubstep(const Model& m, State& s, Workspace& ws, Real T, StageTimes* times) {
  // Forces at (x(n), v(n)) with the analytic length rate.
  {
    StageTimer timer(&times->forces_ns);
    EvaluateForces(m, s, ws, /*filtered=*/false, T);
  }
  StageTimer timer(&times->integrate_ns);
  const int32_t n = ws.num_active;
  if (n == 0) return 0;
  ImplicitBuffers& ib = ws.implicit;

  // Grow the buffers if this active system is the largest yet (the only allocation).
  int64_t need = 0;
  for (int32_t i = 0; i < n; ++i) need += 9 * RowBlocks(m, ws, ws.active[i]);
  if (3 * static_cast<int64_t>(n) > static_cast<int64_t>(ib.rhs.size()) ||
      need > static_cast<int64_t>(ib.values.size())) {
    ++s.warnings.implicit_grew;
    Reserve(ib, std::max<int64_t>(n, static_cast<int64_t>(ib.rhs.size() / 3) * 2),
            std::max<int64_t>(need, static_cast<int64_t>(ib.values.size()) * 2));
  }

  // Assemble A and rhs; warm start from each atom's last dv.
  PrefillDiagonal(m, s, ws, T);
  const int64_t nnz = FillRows(m, s, ws, T);
  for (int32_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) ib.dv[3 * i + c] = ib.atom_dv_guess[3 * ws.active[i] + c];
  }

  bool converged = true;
  const int32_t iterations = SolveCg(ws, 3 * n, nnz, &converged);
  if (!converged) ++s.warnings.cg_not_converged;

  // v(n+1) = v(n) + dv; x(n+1) = x(n) + T v(n+1).
  for (int32_t i = 0; i < n; ++i) {
    const int32_t a = ws.active[i];
    for (int c = 0; c < 3; ++c) {
      const Real dv = ib.dv[3 * i + c];
      ib.atom_dv_guess[3 * a + c] = dv;
      s.atom_vel[3 * a + c] += dv;
      s.atom_pos[3 * a + c] += T * s.atom_vel[3 * a + c];
    }
  }
  return iterations;
}

}  // namespace idms::internal
