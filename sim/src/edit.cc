// Topology edits between steps (thesis 3.2.6): element removal by swap-with-last, keeping the
// Model's CSR adjacency, the State's filter arrays and the Workspace's surface adjacency in step.
#include "idms/sim/edit.h"

#include <algorithm>
#include <functional>

#include "idms/sim/check.h"
#include "idms/sim/model.h"
#include "idms/sim/state.h"
#include "idms/sim/workspace.h"

namespace idms {
namespace {

// Removes `id` from list[adr, adr + num) by swapping it with the range's last entry.
void EraseFromRange(std::vector<int32_t>& list, int32_t adr, int32_t& num, int32_t id) {
  for (int32_t j = 0; j < num; ++j) {
    if (list[adr + j] != id) continue;
    list[adr + j] = list[adr + num - 1];
    --num;
    return;
  }
  IDMS_CHECK(false && "id missing from its adjacency range");
}

void RenameInRange(std::vector<int32_t>& list, int32_t adr, int32_t num, int32_t from, int32_t to) {
  for (int32_t j = 0; j < num; ++j) {
    if (list[adr + j] == from) {
      list[adr + j] = to;
      return;
    }
  }
  IDMS_CHECK(false && "id missing from its adjacency range");
}

// Moves entry `from` of a per-entity array of `width` values to `to`, then drops the tail.
template <class T>
void MoveAndPop(std::vector<T>& v, int32_t from, int32_t to, int width) {
  for (int c = 0; c < width; ++c) v[width * to + c] = v[width * from + c];
  v.resize(v.size() - width);
}

// Swap-removes triangle t from the Model and the Workspace's atom -> triangle lists.
void RemoveTriangle(Model& m, Workspace& ws, int32_t t) {
  for (int c = 0; c < 3; ++c) {
    const int32_t a = m.tri_atoms[3 * t + c];
    EraseFromRange(ws.atom_tri, ws.atom_tri_adr[a], ws.atom_tri_num[a], t);
  }
  const int32_t last = m.num_tris - 1;
  if (t != last) {
    for (int c = 0; c < 3; ++c) {
      const int32_t a = m.tri_atoms[3 * last + c];
      RenameInRange(ws.atom_tri, ws.atom_tri_adr[a], ws.atom_tri_num[a], last, t);
    }
  }
  MoveAndPop(m.tri_atoms, last, t, 3);
  --m.num_tris;
}

// Triangles having both a0 and a1 as vertices lose the edge a0-a1.
int32_t RemoveTrianglesWithEdge(Model& m, Workspace& ws, int32_t a0, int32_t a1) {
  int32_t dropped = 0;
  for (int32_t j = 0; j < ws.atom_tri_num[a0];) {
    const int32_t t = ws.atom_tri[ws.atom_tri_adr[a0] + j];
    const int32_t* v = &m.tri_atoms[3 * t];
    if (v[0] == a1 || v[1] == a1 || v[2] == a1) {
      RemoveTriangle(m, ws, t);  // swaps another triangle into slot j: look at j again
      ++dropped;
    } else {
      ++j;
    }
  }
  return dropped;
}

}  // namespace

int32_t RemoveElement(Model& m, State& s, Workspace& ws, int32_t e) {
  IDMS_CHECK(e >= 0 && e < m.num_elems && ws.num_atoms == m.num_atoms);
  IDMS_CHECK(static_cast<int32_t>(s.elem_len.size()) == m.num_elems);
  const int32_t a0 = m.elem_atoms[2 * e], a1 = m.elem_atoms[2 * e + 1];
  const int32_t dropped = RemoveTrianglesWithEdge(m, ws, a0, a1);

  // Out of its atoms' adjacency; the last element takes its id.
  EraseFromRange(m.atom_elem, m.atom_elem_adr[a0], m.atom_elem_num[a0], e);
  EraseFromRange(m.atom_elem, m.atom_elem_adr[a1], m.atom_elem_num[a1], e);
  const int32_t last = m.num_elems - 1;
  if (e != last) {
    for (int c = 0; c < 2; ++c) {
      const int32_t a = m.elem_atoms[2 * last + c];
      RenameInRange(m.atom_elem, m.atom_elem_adr[a], m.atom_elem_num[a], last, e);
    }
  }
  MoveAndPop(m.elem_atoms, last, e, 2);
  MoveAndPop(m.elem_k, last, e, 1);
  MoveAndPop(m.elem_b, last, e, 1);
  MoveAndPop(m.elem_leq, last, e, 1);
  MoveAndPop(m.elem_home, last, e, 1);
  MoveAndPop(s.elem_len, last, e, 1);
  MoveAndPop(s.elem_rate, last, e, 1);
  // Workspace element flags keep their full size; the vacated last slot is cleared.
  ws.elem_cut[e] = ws.elem_cut[last];
  ws.elem_mark[e] = ws.elem_mark[last];
  ws.elem_cut[last] = ws.elem_mark[last] = 0;
  --m.num_elems;
  return dropped;
}

EditReport ApplyPendingEdits(Model& m, State& s, Workspace& ws) {
  EditReport report;
  IDMS_CHECK(ws.topology_version == m.topology_version);
  // Highest id first: the last element, which moves into a removed slot, is then never pending.
  std::sort(ws.pending_cuts.begin(), ws.pending_cuts.begin() + ws.num_pending_cuts, std::greater<int32_t>());
  for (int32_t i = 0; i < ws.num_pending_cuts; ++i) {
    const int32_t e = ws.pending_cuts[i];
    IDMS_CHECK(ws.elem_cut[e]);
    report.triangles_removed += RemoveElement(m, s, ws, e);
    ++report.elements_removed;
  }
  ws.num_pending_cuts = 0;
  report.topology_changed = report.elements_removed > 0;
  if (report.topology_changed) ws.topology_version = ++m.topology_version;
  return report;
}

}  // namespace idms
