// ReorderForLocality: reverse Cuthill-McKee atoms, elements in the full-mode walk order.
#include "idms/sim/reorder.h"

#include <algorithm>
#include <limits>
#include <numeric>

#include "idms/sim/check.h"

namespace idms {
namespace {

int32_t Other(const Model& m, int32_t e, int32_t a) {
  const int32_t a0 = m.elem_atoms[2 * e];
  return a0 == a ? m.elem_atoms[2 * e + 1] : a0;
}

// Breadth-first levels from `root` over unvisited atoms; returns the last level's atoms and the
// number of levels. `level` is scratch (-1 = unseen), restored before returning.
int32_t Levels(const Model& m, int32_t root, const std::vector<uint8_t>& done, std::vector<int32_t>& level,
               std::vector<int32_t>& queue, std::vector<int32_t>* last) {
  queue.assign(1, root);
  level[root] = 0;
  for (size_t head = 0; head < queue.size(); ++head) {
    const int32_t a = queue[head];
    for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) {
      const int32_t b = Other(m, m.atom_elem[m.atom_elem_adr[a] + j], a);
      if (done[b] || level[b] >= 0) continue;
      level[b] = level[a] + 1;
      queue.push_back(b);
    }
  }
  const int32_t depth = level[queue.back()];
  last->clear();
  for (int32_t a : queue) {
    if (level[a] == depth) last->push_back(a);
    level[a] = -1;
  }
  return depth;
}

// Old atom ids in reverse Cuthill-McKee order, component by component (each from a
// pseudo-peripheral atom: the least-degree atom of the deepest level, until the depth stops
// growing). Ties go to the lower id, so the order is deterministic.
std::vector<int32_t> RcmOrder(const Model& m) {
  const int32_t n = m.num_atoms;
  std::vector<int32_t> by_degree(n);
  std::iota(by_degree.begin(), by_degree.end(), 0);
  std::stable_sort(by_degree.begin(), by_degree.end(),
                   [&](int32_t a, int32_t b) { return m.atom_elem_num[a] < m.atom_elem_num[b]; });
  auto less_degree = [&](int32_t a, int32_t b) {
    return m.atom_elem_num[a] != m.atom_elem_num[b] ? m.atom_elem_num[a] < m.atom_elem_num[b] : a < b;
  };
  std::vector<uint8_t> done(n, 0);
  std::vector<int32_t> level(n, -1), queue, last, order, neighbours;
  order.reserve(n);
  for (int32_t start : by_degree) {
    if (done[start]) continue;
    int32_t root = start;
    int32_t depth = Levels(m, root, done, level, queue, &last);
    for (int iter = 0; iter < 8; ++iter) {
      const int32_t candidate = *std::min_element(last.begin(), last.end(), less_degree);
      std::vector<int32_t> candidate_last;
      const int32_t candidate_depth = Levels(m, candidate, done, level, queue, &candidate_last);
      if (candidate_depth <= depth) break;
      root = candidate, depth = candidate_depth, last.swap(candidate_last);
    }
    // Cuthill-McKee from the root: each atom's unvisited neighbours by increasing degree.
    const size_t first = order.size();
    order.push_back(root);
    done[root] = 1;
    for (size_t head = first; head < order.size(); ++head) {
      const int32_t a = order[head];
      neighbours.clear();
      for (int32_t j = 0; j < m.atom_elem_num[a]; ++j) {
        const int32_t b = Other(m, m.atom_elem[m.atom_elem_adr[a] + j], a);
        if (!done[b]) done[b] = 1, neighbours.push_back(b);
      }
      std::sort(neighbours.begin(), neighbours.end(), less_degree);
      order.insert(order.end(), neighbours.begin(), neighbours.end());
    }
  }
  std::reverse(order.begin(), order.end());
  return order;
}

}  // namespace

Model ReorderForLocality(const Model& model, const ReorderOptions& options, Reordering* map) {
  const Model& m = model;
  IDMS_CHECK(static_cast<int32_t>(m.atom_elem_num.size()) == m.num_atoms);

  // Atoms: new position k holds old atom order[k].
  std::vector<int32_t> order;
  if (options.atoms) {
    order = RcmOrder(m);
  } else {
    order.resize(m.num_atoms);
    std::iota(order.begin(), order.end(), 0);
  }
  IDMS_CHECK(static_cast<int32_t>(order.size()) == m.num_atoms);
  std::vector<int32_t> atom_new(m.num_atoms);
  for (int32_t k = 0; k < m.num_atoms; ++k) atom_new[order[k]] = k;

  // Elements: by lowest free endpoint (the group the step's walk puts them in), then the other
  // endpoint, then the old id; elements without a free endpoint last.
  constexpr int32_t kNoGroup = std::numeric_limits<int32_t>::max();
  std::vector<int32_t> group(m.num_elems), other(m.num_elems), elem_order(m.num_elems);
  for (int32_t e = 0; e < m.num_elems; ++e) {
    const int32_t a0 = m.elem_atoms[2 * e], a1 = m.elem_atoms[2 * e + 1];
    const int32_t n0 = atom_new[a0], n1 = atom_new[a1];
    const bool free0 = !m.atom_fixed[a0], free1 = !m.atom_fixed[a1];
    group[e] = free0 && free1 ? std::min(n0, n1) : free0 ? n0 : free1 ? n1 : kNoGroup;
    other[e] = group[e] == n0 ? n1 : n0;
  }
  std::iota(elem_order.begin(), elem_order.end(), 0);
  std::sort(elem_order.begin(), elem_order.end(), [&](int32_t a, int32_t b) {
    if (group[a] != group[b]) return group[a] < group[b];
    if (other[a] != other[b]) return other[a] < other[b];
    return a < b;
  });

  // The renumbered model; FinalizeModel derives the rest.
  Model out;
  out.name = m.name;
  out.topology_version = m.topology_version;
  out.atom_pos_eq.resize(3 * static_cast<size_t>(m.num_atoms));
  out.atom_mass.resize(m.num_atoms);
  out.atom_fixed.resize(m.num_atoms);
  out.atom_external.resize(m.num_atoms);
  for (int32_t k = 0; k < m.num_atoms; ++k) {
    const int32_t a = order[k];
    for (int c = 0; c < 3; ++c) out.atom_pos_eq[3 * k + c] = m.atom_pos_eq[3 * a + c];
    out.atom_mass[k] = m.atom_mass[a];
    out.atom_fixed[k] = m.atom_fixed[a];
    out.atom_external[k] = m.atom_external[a];
  }
  out.elem_atoms.resize(2 * static_cast<size_t>(m.num_elems));
  out.elem_k.resize(m.num_elems);
  out.elem_b.resize(m.num_elems);
  std::vector<int32_t> elem_new(m.num_elems);
  for (int32_t k = 0; k < m.num_elems; ++k) {
    const int32_t e = elem_order[k];
    elem_new[e] = k;
    out.elem_atoms[2 * k] = atom_new[m.elem_atoms[2 * e]];
    out.elem_atoms[2 * k + 1] = atom_new[m.elem_atoms[2 * e + 1]];
    out.elem_k[k] = m.elem_k[e];
    out.elem_b[k] = m.elem_b[e];
  }
  out.tri_atoms.resize(m.tri_atoms.size());
  for (size_t i = 0; i < m.tri_atoms.size(); ++i) out.tri_atoms[i] = atom_new[m.tri_atoms[i]];
  FinalizeModel(out);
  if (map != nullptr) {
    map->atom_new_id = std::move(atom_new);
    map->elem_new_id = std::move(elem_new);
  }
  return out;
}

}  // namespace idms
