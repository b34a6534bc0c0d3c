// Readers and writers for the thesis's .fem / .plg files (appendix B) and Wavefront .obj surfaces.
// Every reader validates everything and reports the first error as FILE:LINE:COL: what was
// expected; on error the output model is left untouched (nothing half-loaded is ever used).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "idms/sim/model.h"

namespace idms {

// Where and what went wrong. line and col are 1-based; 0 means "the whole file".
struct LoadError {
  std::string file;
  int line = 0;
  int col = 0;
  std::string message;

  // "file:line:col: message" (line and col omitted when 0).
  std::string ToString() const;
};

struct ReadOptions {
  int64_t max_bytes = int64_t{512} << 20;  // a larger file is rejected before it is read
  double plg_tolerance = 1e-3;             // max |plg vertex - fem external atom|, model units
};

// A polygon surface as read from a .plg or .obj: vertices and triangles (polygons with more
// than three sides are fan-triangulated on read).
struct SurfaceMesh {
  std::string name;
  std::vector<double> vert_pos;    // (num_verts x 3), model units
  std::vector<int32_t> tri_verts;  // (num_tris x 3), vertex ids, counter-clockwise seen from outside
  std::vector<int32_t> vert_line;  // (num_verts), 1-based source line of each vertex, for errors
  int32_t num_verts() const { return static_cast<int32_t>(vert_pos.size() / 3); }
  int32_t num_tris() const { return static_cast<int32_t>(tri_verts.size() / 3); }
};

// Parsers of in-memory text. `file` names the source in error messages.
bool ParseFem(std::string_view text, std::string_view file, Model* model, LoadError* error);
bool ParsePlg(std::string_view text, std::string_view file, SurfaceMesh* mesh, LoadError* error);
bool ParseObj(std::string_view text, std::string_view file, SurfaceMesh* mesh, LoadError* error);

// Checks that `mesh` is the surface of `model` (vertex i = i-th external atom, positions within
// tolerance) and, if so, sets the model's triangles. `file` and mesh.vert_line locate the error.
bool AttachSurface(const SurfaceMesh& mesh, std::string_view file, double tolerance, Model* model, LoadError* error);

// A pair in memory (a library's blobs): NAME.fem and NAME.plg through the parsers, the surface
// attached at the default tolerance. Errors name NAME.fem or NAME.plg.
bool ParseModelText(std::string_view fem, std::string_view plg, const std::string& name, Model* model,
                    LoadError* error);

// Reads a whole file, refusing it when larger than max_bytes, empty, or not text.
bool ReadTextFile(const std::string& path, int64_t max_bytes, std::string* text, LoadError* error);

// Loads FEM_PATH and, if plg_path is non-empty, its surface. FinalizeModel has been called.
bool LoadModel(const std::string& fem_path, const std::string& plg_path, const ReadOptions& options, Model* model,
               LoadError* error);

// "PREFIX" or "PREFIX.fem" -> the .fem and .plg paths of the pair.
void ModelPaths(const std::string& prefix_or_fem, std::string* fem_path, std::string* plg_path);

// Writers: exact text (shortest round-trip decimal), so write -> read gives the same model bit
// for bit and write -> read -> write gives identical bytes. WritePlg writes rest positions.
std::string WriteFem(const Model& model);
std::string WritePlg(const Model& model);
std::string WriteObj(const Model& model);
// The surface at `positions` (num_atoms x 3), e.g. a deformed state, as Wavefront .obj.
std::string WriteObj(const Model& model, const double* positions);

// Writes PREFIX.fem and PREFIX.plg, each through a temporary file and rename, so a reader
// never sees a half-written file. Returns false and sets *error on failure.
bool SaveModel(const Model& model, const std::string& prefix, std::string* error);
bool WriteTextFileAtomic(const std::string& path, std::string_view text, std::string* error);

}  // namespace idms
