// Vertex positions of a collision mesh file, and the box that bounds them:
// what the URDF importer fits to a `<mesh>` collision (docs/contacts.md).
//
// Formats, chosen by the file's extension (any letter case):
// - .stl, binary: an 80-byte header, a uint32 triangle count n, then 50
//   bytes a triangle (normal, 3 vertices: 12 float32, then a uint16), all
//   little-endian. A file of exactly 84 + 50 n bytes is binary, even when
//   its header begins with "solid" (many exporters write that).
// - .stl, ASCII: otherwise, a text file (no NUL byte) beginning with
//   "solid"; every `vertex x y z`. Anything else is a broken binary file.
// - .obj: Wavefront OBJ; every `v x y z [w]` line (w ignored; `vt`, `vn`
//   are not positions).
// - .dae: COLLADA; for each <geometry><mesh>, the <source> that its
//   <vertices><input semantic="POSITION"> names, read through the source's
//   <accessor> (count, stride, offset; the first 3 values of each vertex);
//   geometries without a <mesh> (splines, convex meshes) are passed over.
//   The document's <asset><unit meter> scales the positions to metres, and
//   its <asset><up_axis> turns them to z up (the URDF convention) by the
//   rotation that maps the file's "right", "up" and "in" axes (as the spec
//   names them) onto Z_UP's: Z_UP as is, Y_UP (x, y, z) -> (x, -z, y) (+90
//   degrees about x), X_UP (x, y, z) -> (-y, -z, x). Absent, they are 1 m
//   and Y_UP, the spec's defaults. Node transforms in
//   <library_visual_scenes> and <asset>s inside geometries are ignored: the
//   positions are those the geometry holds.
// Every vertex counts, whether or not a face uses it.
#pragma once

#include <Eigen/Geometry>

#include <stdexcept>
#include <string>
#include <vector>

namespace lockstep {

// A mesh file that cannot be used; what() is the reason, without the path.
class MeshFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The vertex positions of `path`, in metres, z up (see above). Throws
// MeshFileError when the file cannot be read, its extension is none of the
// above, it does not parse, a coordinate is not finite or it has no vertex.
std::vector<Eigen::Vector3d> read_mesh_vertices(const std::string& path);

// The axis-aligned box, in the mesh's own frame, of the vertices of `path`
// each scaled by `scale` per axis (URDF `<mesh scale>`; a negative factor
// mirrors). A flat mesh gives a box of zero extent along its normal. Throws
// as read_mesh_vertices.
Eigen::AlignedBox3d mesh_bounds(const std::string& path, const Eigen::Vector3d& scale);

}  // namespace lockstep
