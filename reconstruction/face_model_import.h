// Conversion of the original ICT-FaceKit model folder into the Basel-layout
// HDF5 file that FaceModel::Load reads (layout: ../shared/data/README.md), so
// a user can rebuild ict_face_model.h5 from a checkout of ICT-FaceKit
// (USC ICT Vision & Graphics Lab, MIT licence), or from a newer release of it.
//
// What the source folder (FaceXModel/) holds, and how each part is mapped:
// - generic_neutral_mesh.obj: the neutral face in centimetres, +y up, looking
//   toward +z (the head frame of DESIGN.md, so only the unit changes).
//   Polygons, mostly quads plus some triangles, with per-corner texture
//   coordinates ("f v/vt ..."). 26719 vertices and 26384 polygons in the
//   released model. -> shape/representer/points, shape/model/mean; polygons
//   split as fans from their first corner, (c0, c1, c2), (c0, c2, c3), ...
//   -> shape/representer/cells; the vt list -> uv/coords, the per-corner vt
//   indices split the same way -> uv/cells.
// - identity000.obj, identity001.obj, ...: the neutral moved by one standard
//   deviation along each identity PCA mode (ICT-FaceKit's own scripts use
//   identityK - neutral as mode K with weights drawn from N(0, 1)). With
//   delta_K that difference in metres, the Basel layout stores
//   pcaBasis[:, K] = delta_K / |delta_K| and pcaVariance[K] = |delta_K|^2,
//   so mean + pcaBasis diag(sqrt(pcaVariance)) alpha reproduces the toolkit.
// - <name>.obj for each expression named in vertex_indices.json
//   ("expressions": ARKit-style names such as jawOpen, eyeBlink_L): blendshape
//   targets with weights in [0, 1], stored the same way under
//   expression/model (mean zero) with their names in expression/names.
// - vertex_indices.json: "idx_to_landmark_verts" (68 vertex indices in iBUG
//   order) -> landmarks/ibug68; "idx_to_rigid_landmark_idx" (indices into
//   those 68) -> landmarks/ibug68_rigid; "idx_to_rigid_verts" ->
//   masks/rigid_vertices; "idx_to_fitting_verts" -> masks/fitting_vertices.
//   Other keys (fitting_expressions, incompatibilities,
//   idx_to_lap_rigid_verts, ...) are not used.
// - regions/<name>: the 17 parts of the released topology (face,
//   head_and_neck, mouth_socket, teeth, eyeball_left, ...) as listed in
//   ICT-FaceKit's README by vertex and polygon range; written only when the
//   neutral mesh has that topology, with polygon ranges turned into the
//   ranges of their triangles.
#pragma once

#include <string>

#include "core/status.h"

namespace headforge {

struct IctImportOptions {
  // Metres per OBJ unit; the ICT-FaceKit OBJs are in centimetres.
  double scale = 0.01;
  // Read only identity000 .. identity(K-1); 0 reads every identity shape.
  int max_identities = 0;

  Status Check() const;
};

struct IctImportSummary {
  int num_vertices = 0;
  int num_polygons = 0;   // in generic_neutral_mesh.obj
  int num_triangles = 0;  // after splitting the polygons
  int num_uvs = 0;        // 0 when the neutral mesh has no texture coordinates
  int num_identities = 0;
  int num_expressions = 0;
  int num_landmarks = 0;
  int num_regions = 0;
};

// Reads the ICT-FaceKit folder `dir` and writes the face model to `out_path`
// (through a temporary file in the same folder, renamed when complete; an
// earlier file there stays untouched on failure). `summary` may be null.
// Errors: InvalidArgument (bad options, `dir` is not a folder), NotFound (no
// folder, no generic_neutral_mesh.obj or vertex_indices.json, a listed
// expression OBJ missing), DataError (malformed OBJ or JSON, vertex counts
// that differ between OBJs, indices out of range), IoError (cannot write).
Status ImportIctFaceKit(const std::string& dir, const std::string& out_path, const IctImportOptions& options,
                        IctImportSummary* summary = nullptr);

}  // namespace headforge
