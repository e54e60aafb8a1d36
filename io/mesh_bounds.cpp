#include "io/mesh_bounds.hpp"

#include "io/number_text.hpp"

#include <tinyxml2.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string_view>

namespace lockstep {

namespace {

using tinyxml2::XMLElement;

// The whitespace-separated words of a text, one at a time.
class Words {
 public:
  explicit Words(std::string_view text) : p_(text.data()), end_(text.data() + text.size()) {}

  bool at_end() {
    while (p_ < end_ && std::isspace(static_cast<unsigned char>(*p_))) ++p_;
    return p_ == end_;
  }

  // The next word; empty at the end.
  std::string_view next() {
    at_end();
    const char* start = p_;
    while (p_ < end_ && !std::isspace(static_cast<unsigned char>(*p_))) ++p_;
    return std::string_view(start, static_cast<std::size_t>(p_ - start));
  }

  // The next word as a number; throws, naming `where`, when it is not one.
  double number(const std::string& where) {
    std::string_view w = next();
    if (w.empty()) throw MeshFileError(where + ": a number is missing");
    double x = 0;
    const std::string why = parse_number(w, x);
    if (!why.empty()) throw MeshFileError(where + ": '" + std::string(w) + "': " + why);
    return x;
  }

  Eigen::Vector3d point(const std::string& where) {
    Eigen::Vector3d p;
    for (int k = 0; k < 3; ++k) p[k] = number(where);
    return p;
  }

 private:
  const char* p_;
  const char* end_;
};

// Binary STL fields are little-endian whatever the machine.
std::uint32_t le_uint32(const char* p) {
  std::uint32_t x = 0;
  for (int k = 3; k >= 0; --k) x = x << 8 | static_cast<unsigned char>(p[k]);
  return x;
}

float le_float32(const char* p) {
  const std::uint32_t bits = le_uint32(p);
  float x;
  std::memcpy(&x, &bits, sizeof x);
  return x;
}

std::vector<Eigen::Vector3d> read_stl(std::string_view bytes) {
  std::vector<Eigen::Vector3d> points;
  // Binary when the size matches the triangle count at byte 80: binary
  // headers often begin with "solid" too, so that word alone proves nothing.
  const std::uint64_t n = bytes.size() >= 84 ? le_uint32(bytes.data() + 80) : 0;
  if (bytes.size() == 84 + 50 * n) {
    points.reserve(3 * n);
    for (std::uint64_t t = 0; t < n; ++t) {
      const char* vertex = bytes.data() + 84 + 50 * t + 12;  // past the normal
      for (int v = 0; v < 3; ++v, vertex += 12)
        points.emplace_back(le_float32(vertex), le_float32(vertex + 4), le_float32(vertex + 8));
    }
    return points;
  }
  // ASCII is text; a binary file practically always holds NUL bytes (zero
  // attribute counts, the low bytes of short floats).
  Words words(bytes);
  if (words.next() != "solid" || bytes.find('\0') != std::string_view::npos) {
    if (bytes.size() < 84)
      throw MeshFileError("neither ASCII STL (text beginning with \"solid\") nor binary (84-byte header at least)");
    throw MeshFileError("not ASCII STL; as binary STL, its header counts " + std::to_string(n) + " triangles (84 + 50 x " +
                        std::to_string(n) + " = " + std::to_string(84 + 50 * n) + " bytes) but the file has " +
                        std::to_string(bytes.size()) + " bytes");
  }
  for (std::string_view w = words.next(); !w.empty(); w = words.next())
    if (w == "vertex") points.push_back(words.point("ASCII STL vertex " + std::to_string(points.size())));
  return points;
}

std::vector<Eigen::Vector3d> read_obj(std::string_view text) {
  std::vector<Eigen::Vector3d> points;
  int line = 1;
  for (std::size_t start = 0; start < text.size(); ++line) {
    const std::size_t stop = std::min(text.find('\n', start), text.size());
    Words words(text.substr(start, stop - start));
    if (words.next() == "v") points.push_back(words.point("OBJ line " + std::to_string(line)));
    start = stop + 1;
  }
  return points;
}

// The rotation from a COLLADA <up_axis> to z up. The spec's axes (right, up,
// in): X_UP (-y, +x, +z), Y_UP (+x, +y, +z), Z_UP (+x, +z, -y); the rotation
// maps each file's right, up and in onto Z_UP's.
Eigen::Matrix3d z_up_from(std::string_view up_axis) {
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  if (up_axis == "Y_UP") {
    r << 1, 0, 0, 0, 0, -1, 0, 1, 0;  // (x, y, z) -> (x, -z, y)
  } else if (up_axis == "X_UP") {
    r << 0, -1, 0, 0, 0, -1, 1, 0, 0;  // (x, y, z) -> (-y, -z, x)
  } else if (up_axis != "Z_UP") {
    throw MeshFileError("COLLADA <up_axis> '" + std::string(up_axis) + "' is none of X_UP, Y_UP, Z_UP");
  }
  return r;
}

std::string attribute(const XMLElement* e, const char* name) {
  const char* value = e->Attribute(name);
  return value ? value : "";
}

// The positions of one COLLADA <mesh>, as the file writes them.
std::vector<Eigen::Vector3d> mesh_positions(const XMLElement* mesh, const std::string& where) {
  // <vertices><input semantic="POSITION" source="#id"/> names a <source id="id"> of the mesh.
  const XMLElement* vertices = mesh->FirstChildElement("vertices");
  const XMLElement* input = vertices ? vertices->FirstChildElement("input") : nullptr;
  while (input && attribute(input, "semantic") != "POSITION") input = input->NextSiblingElement("input");
  if (!input) throw MeshFileError(where + ": no <vertices><input semantic=\"POSITION\">");
  const std::string ref = attribute(input, "source");
  const XMLElement* source = mesh->FirstChildElement("source");
  while (source && "#" + attribute(source, "id") != ref) source = source->NextSiblingElement("source");
  const XMLElement* array = source ? source->FirstChildElement("float_array") : nullptr;
  if (!array) throw MeshFileError(where + ": no <source> with a <float_array> for POSITION source '" + ref + "'");
  std::vector<double> values;
  Words words(array->GetText() ? array->GetText() : "");
  while (!words.at_end()) values.push_back(words.number(where + " <float_array>"));

  // The accessor reads `count` vertices of `stride` values from `offset`; x,
  // y, z are the first 3 of each. Without one, the array is x y z triples.
  unsigned count = static_cast<unsigned>(values.size() / 3), stride = 3, offset = 0;
  const XMLElement* technique = source->FirstChildElement("technique_common");
  if (const XMLElement* accessor = technique ? technique->FirstChildElement("accessor") : nullptr) {
    count = accessor->UnsignedAttribute("count");
    stride = accessor->UnsignedAttribute("stride", 1);
    offset = accessor->UnsignedAttribute("offset");
  }
  if (stride < 3) throw MeshFileError(where + ": POSITION accessor stride " + std::to_string(stride) + " < 3");
  if (count > 0 && offset + std::uint64_t{count - 1} * stride + 3 > values.size())
    throw MeshFileError(where + ": POSITION accessor reads past its <float_array> of " + std::to_string(values.size()) +
                        " values");
  std::vector<Eigen::Vector3d> points;
  for (std::size_t i = 0; i < count; ++i) points.emplace_back(Eigen::Vector3d::Map(&values[offset + i * stride]));
  return points;
}

std::vector<Eigen::Vector3d> read_dae(std::string_view text) {
  tinyxml2::XMLDocument doc;
  if (doc.Parse(text.data(), text.size()) != tinyxml2::XML_SUCCESS)
    throw MeshFileError("COLLADA: line " + std::to_string(doc.ErrorLineNum()) + ": not valid XML: " + doc.ErrorStr());
  const XMLElement* collada = doc.RootElement();
  if (!collada || std::string_view(collada->Name()) != "COLLADA")
    throw MeshFileError("COLLADA: the root element is not <COLLADA>");

  // The document's unit and up axis (absent: 1 m and Y_UP, the spec's defaults).
  double meter = 1.0;
  std::string up_axis = "Y_UP";
  if (const XMLElement* asset = collada->FirstChildElement("asset")) {
    const XMLElement* unit = asset->FirstChildElement("unit");
    if (unit && unit->Attribute("meter")) {
      meter = Words(unit->Attribute("meter")).number("COLLADA <unit meter>");
      if (!(meter > 0 && std::isfinite(meter))) throw MeshFileError("COLLADA <unit meter> is not a positive number");
    }
    const XMLElement* up = asset->FirstChildElement("up_axis");
    if (up && up->GetText()) up_axis = std::string(Words(up->GetText()).next());
  }
  const Eigen::Matrix3d to_urdf = meter * z_up_from(up_axis);

  std::vector<Eigen::Vector3d> points;
  for (const XMLElement* lib = collada->FirstChildElement("library_geometries"); lib;
       lib = lib->NextSiblingElement("library_geometries"))
    for (const XMLElement* g = lib->FirstChildElement("geometry"); g; g = g->NextSiblingElement("geometry"))
      if (const XMLElement* mesh = g->FirstChildElement("mesh"))
        for (const Eigen::Vector3d& p : mesh_positions(mesh, "COLLADA geometry '" + attribute(g, "id") + "'"))
          points.push_back(to_urdf * p);
  return points;
}

}  // namespace

std::vector<Eigen::Vector3d> read_mesh_vertices(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext != ".stl" && ext != ".obj" && ext != ".dae")
    throw MeshFileError((ext.empty() ? std::string("no extension") : "extension '" + ext + "'") +
                        ": not a mesh format read here (.stl, .obj, .dae)");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw MeshFileError("cannot open the file");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (in.bad()) throw MeshFileError("cannot read the file");
  const std::string text = bytes.str();

  const std::vector<Eigen::Vector3d> points = ext == ".stl" ? read_stl(text) : ext == ".obj" ? read_obj(text) : read_dae(text);
  if (points.empty()) throw MeshFileError("no vertices");
  for (const Eigen::Vector3d& p : points)
    if (!p.allFinite()) throw MeshFileError("a vertex coordinate is not finite");
  return points;
}

Eigen::AlignedBox3d mesh_bounds(const std::string& path, const Eigen::Vector3d& scale) {
  Eigen::AlignedBox3d box;  // empty
  for (const Eigen::Vector3d& p : read_mesh_vertices(path)) box.extend(p.cwiseProduct(scale));
  return box;
}

}  // namespace lockstep
