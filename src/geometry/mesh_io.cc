#include "inhand/geometry/mesh_io.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/DefaultLogger.hpp>
#include <assimp/Importer.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"

namespace inhand {

namespace fs = std::filesystem;

namespace {

// A whitespace-separated number starting at *p (advanced past it); false when there is none.
bool parseNumber(const char*& p, const char* end, double* out) {
  while (p < end && (*p == ' ' || *p == '\t' || *p == '\r')) ++p;
  if (p >= end || *p == '\n') return false;
  char* stop = nullptr;
  std::string token;
  const char* q = p;
  while (q < end && !std::isspace(static_cast<unsigned char>(*q))) ++q;
  token.assign(p, q);
  *out = std::strtod(token.c_str(), &stop);
  if (stop == token.c_str() || *stop != '\0') return false;
  p = q;
  return true;
}

// What an OBJ says about its surface's colour: texture coordinates, each triangle's corners'
// coordinates (-1: none) and material (-1: none), and the material libraries named.
struct ObjColours {
  std::vector<Vec2f> vt;
  std::vector<int> corner_vt;  // 3 per triangle
  std::vector<std::string> material_names;
  std::vector<int> triangle_material;
  std::vector<std::string> mtllibs;
};

// The rest of the line after a keyword, trimmed.
std::string restOfLine(const char* q, const char* eol) {
  while (q < eol && (*q == ' ' || *q == '\t')) ++q;
  while (eol > q && std::isspace(static_cast<unsigned char>(eol[-1]))) --eol;
  return std::string(q, eol);
}

bool keyword(const char* q, const char* eol, const char* word) {
  const size_t n = std::strlen(word);
  return size_t(eol - q) > n && std::strncmp(q, word, n) == 0 && (q[n] == ' ' || q[n] == '\t');
}

// Wavefront OBJ: `v x y z [w]` and `f` with `i`, `i/t`, `i//n` or `i/t/n` corners (negative:
// relative to the end), polygons fan-triangulated; with `colours`, also `vt`, `usemtl` and
// `mtllib`; every other statement ignored. Errors name the line.
TriangleMesh readObj(const fs::path& path, ObjColours* colours = nullptr) {
  const std::string data = readTextFile(path);
  TriangleMesh mesh;
  const char* p = data.data();
  const char* end = p + data.size();
  int lineNo = 0;
  auto fail = [&](const std::string& what) {
    return Error(path.string() + ": line " + std::to_string(lineNo) + ": " + what);
  };
  std::vector<int> corners, cornerVt;
  int material = -1;
  while (p < end) {
    ++lineNo;
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', size_t(end - p)));
    if (!eol) eol = end;
    const char* q = p;
    while (q < eol && (*q == ' ' || *q == '\t')) ++q;
    if (eol - q >= 2 && q[0] == 'v' && (q[1] == ' ' || q[1] == '\t')) {
      q += 2;
      double c[3];
      for (double& x : c)
        if (!parseNumber(q, eol, &x)) throw fail("a vertex needs three numbers (v x y z)");
      mesh.vertices.emplace_back(float(c[0]), float(c[1]), float(c[2]));
    } else if (colours && keyword(q, eol, "vt")) {
      q += 3;
      double c[2];
      for (double& x : c)
        if (!parseNumber(q, eol, &x)) throw fail("a texture coordinate needs two numbers (vt u v)");
      colours->vt.emplace_back(float(c[0]), float(c[1]));
    } else if (colours && keyword(q, eol, "usemtl")) {
      const std::string name = restOfLine(q + 6, eol);
      auto it = std::find(colours->material_names.begin(), colours->material_names.end(), name);
      material = int(it - colours->material_names.begin());
      if (it == colours->material_names.end()) colours->material_names.push_back(name);
    } else if (colours && keyword(q, eol, "mtllib")) {
      colours->mtllibs.push_back(restOfLine(q + 6, eol));
    } else if (eol - q >= 2 && q[0] == 'f' && (q[1] == ' ' || q[1] == '\t')) {
      q += 2;
      corners.clear();
      cornerVt.clear();
      while (true) {
        while (q < eol && (*q == ' ' || *q == '\t' || *q == '\r')) ++q;
        if (q >= eol) break;
        char* stop = nullptr;
        const long i = std::strtol(q, &stop, 10);
        if (stop == q) throw fail("a face corner is not a vertex index");
        const long n = long(mesh.vertices.size());
        const long index = i > 0 ? i - 1 : n + i;  // 1-based, or relative when negative
        if (i == 0 || index < 0 || index >= n)
          throw fail("face vertex index " + std::to_string(i) + " is not one of the " +
                     std::to_string(n) + " vertices so far");
        corners.push_back(int(index));
        q = stop;
        int vt = -1;
        if (colours && q < eol && *q == '/' && q + 1 < eol && q[1] != '/') {
          const long t = std::strtol(q + 1, &stop, 10);
          const long nt = long(colours->vt.size());
          const long ti = t > 0 ? t - 1 : nt + t;
          if (stop == q + 1 || t == 0 || ti < 0 || ti >= nt)
            throw fail("face texture index is not one of the " + std::to_string(nt) +
                       " texture coordinates so far");
          vt = int(ti);
        }
        cornerVt.push_back(vt);
        while (q < eol && !std::isspace(static_cast<unsigned char>(*q))) ++q;  // /t/n
      }
      if (corners.size() < 3) throw fail("a face needs three corners or more");
      for (size_t k = 1; k + 1 < corners.size(); ++k) {
        mesh.triangles.emplace_back(corners[0], corners[k], corners[k + 1]);
        if (colours) {
          for (size_t c : {size_t(0), k, k + 1}) colours->corner_vt.push_back(cornerVt[c]);
          colours->triangle_material.push_back(material);
        }
      }
    }
    p = eol + (eol < end ? 1 : 0);
  }
  return mesh;
}

// STL, binary (84-byte header and count, 50 bytes per triangle: the size must agree) or ASCII
// (`vertex x y z`, three per facet).
TriangleMesh readStl(const fs::path& path) {
  const std::string data = readTextFile(path);
  TriangleMesh mesh;
  if (data.size() >= 84) {
    uint32_t n = 0;
    std::memcpy(&n, data.data() + 80, 4);
    if (data.size() == 84 + 50 * uint64_t(n)) {
      mesh.vertices.reserve(3 * size_t(n));
      for (uint32_t t = 0; t < n; ++t) {
        const char* f = data.data() + 84 + 50 * size_t(t) + 12;
        for (int k = 0; k < 3; ++k) {
          float v[3];
          std::memcpy(v, f + 12 * k, 12);
          mesh.vertices.emplace_back(v[0], v[1], v[2]);
        }
        mesh.triangles.emplace_back(int(3 * t), int(3 * t + 1), int(3 * t + 2));
      }
      return mesh;
    }
  }
  if (data.compare(0, 5, "solid") != 0)
    throw Error(path.string() + ": not an STL file (binary: " + std::to_string(data.size()) +
                " bytes do not match its triangle count; ASCII: no 'solid')");
  std::istringstream in(data);
  std::string word;
  int inFacet = 0;
  while (in >> word) {
    if (word == "vertex") {
      double x, y, z;
      if (!(in >> x >> y >> z))
        throw Error(path.string() + ": STL vertex " + std::to_string(mesh.vertices.size() + 1) +
                    " needs three numbers");
      mesh.vertices.emplace_back(float(x), float(y), float(z));
      if (++inFacet == 3) {
        const int b = int(mesh.vertices.size()) - 3;
        mesh.triangles.emplace_back(b, b + 1, b + 2);
      }
    } else if (word == "facet") {
      inFacet = 0;
    } else if (word == "endfacet" && inFacet != 3) {
      throw Error(path.string() + ": STL facet " + std::to_string(mesh.triangles.size() + 1) +
                  " has " + std::to_string(inFacet) + " vertices, not 3");
    }
  }
  return mesh;
}

}  // namespace

TriangleMesh importMesh(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error(path.string() + ": no such mesh file");
  if (fs::is_directory(path, ec)) throw Error(path.string() + ": is a directory, not a mesh file");
  if (fs::file_size(path, ec) == 0) throw Error(path.string() + ": mesh file is empty");
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  // PLY: our own reader (assimp 5.2's PLY importer crashes on files with extra per-vertex
  // properties such as inhand's variance + colour models, and hangs on some malformed
  // big-endian files found by fuzzing).
  if (ext == ".ply") return welded(readPly(path).mesh);
  // OBJ and STL: our own readers too (assimp 5.2's OBJ importer leaks, and takes gigabytes, on
  // some malformed files found by fuzzing); their errors name the line.
  if (ext == ".obj" || ext == ".stl") {
    TriangleMesh mesh = ext == ".obj" ? readObj(path) : readStl(path);
    std::string problem = validateMesh(mesh);
    if (!problem.empty()) throw Error(path.string() + ": mesh " + problem);
    return welded(mesh);
  }
  Assimp::Importer importer;
  importer.SetPropertyInteger(AI_CONFIG_PP_RVC_FLAGS,
                              aiComponent_NORMALS | aiComponent_COLORS | aiComponent_TEXCOORDS |
                                  aiComponent_TANGENTS_AND_BITANGENTS | aiComponent_MATERIALS);
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                              aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  const aiScene* scene =
      importer.ReadFile(path.string(), aiProcess_Triangulate | aiProcess_RemoveComponent |
                                           aiProcess_JoinIdenticalVertices | aiProcess_SortByPType |
                                           aiProcess_FindDegenerates);
  if (!scene || !scene->mRootNode)
    throw Error(path.string() + ": cannot read mesh (" + importer.GetErrorString() + ")");
  TriangleMesh out;
  std::function<void(const aiNode*, const aiMatrix4x4&)> visit = [&](const aiNode* node,
                                                                     const aiMatrix4x4& parent) {
    aiMatrix4x4 T = parent * node->mTransformation;
    for (unsigned k = 0; k < node->mNumMeshes; ++k) {
      const aiMesh* m = scene->mMeshes[node->mMeshes[k]];
      if (!(m->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
      int base = static_cast<int>(out.vertices.size());
      for (unsigned i = 0; i < m->mNumVertices; ++i) {
        aiVector3D v = T * m->mVertices[i];
        out.vertices.emplace_back(v.x, v.y, v.z);
      }
      for (unsigned i = 0; i < m->mNumFaces; ++i) {
        const aiFace& f = m->mFaces[i];
        if (f.mNumIndices != 3) continue;
        out.triangles.emplace_back(base + int(f.mIndices[0]), base + int(f.mIndices[1]),
                                   base + int(f.mIndices[2]));
      }
    }
    for (unsigned c = 0; c < node->mNumChildren; ++c) visit(node->mChildren[c], T);
  };
  visit(scene->mRootNode, aiMatrix4x4());
  std::string problem = validateMesh(out);
  if (!problem.empty()) throw Error(path.string() + ": mesh " + problem);
  return welded(out);
}

std::array<uint8_t, 3> confidenceColor(float variance_m2) {
  // Log-scale blend between σ = 0.3 mm (grey) and σ = 5 cm (red).
  constexpr double kSigmaGrey = 0.0003, kSigmaRed = 0.05;
  double sigma = std::sqrt(std::max(0.f, variance_m2));
  double s =
      sigma <= kSigmaGrey ? 0.0 : std::log(sigma / kSigmaGrey) / std::log(kSigmaRed / kSigmaGrey);
  s = std::clamp(s, 0.0, 1.0);
  const double grey[3] = {170, 170, 170}, red[3] = {220, 20, 20};
  std::array<uint8_t, 3> c;
  for (int k = 0; k < 3; ++k) c[k] = uint8_t(std::lround(grey[k] + s * (red[k] - grey[k])));
  return c;
}

void writeStl(const fs::path& path, const TriangleMesh& mesh) {
  if (mesh.triangles.size() > 0xffffffffu) throw Error(path.string() + ": too many triangles");
  writeFileAtomically(path, [&](const fs::path& tmp) {
    std::string buf(84 + 50 * mesh.triangles.size(), '\0');
    const std::string header = "binary STL written by inhand; units: metres";
    std::memcpy(buf.data(), header.data(), header.size());
    const uint32_t n = uint32_t(mesh.triangles.size());
    std::memcpy(buf.data() + 80, &n, 4);
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      const Tri& f = mesh.triangles[t];
      const Vec3f &a = mesh.vertices[f[0]], &b = mesh.vertices[f[1]], &c = mesh.vertices[f[2]];
      Vec3f normal = (b - a).cross(c - a);
      normal = normal.norm() > 0 ? Vec3f(normal.normalized()) : Vec3f::Zero();
      char* p = buf.data() + 84 + 50 * t;
      for (const Vec3f* v : std::array<const Vec3f*, 4>{&normal, &a, &b, &c}) {
        std::memcpy(p, v->data(), 12);
        p += 12;
      }
    }
    std::ofstream out(tmp, std::ios::binary);
    if (!out.write(buf.data(), std::streamsize(buf.size())))
      throw Error(path.string() + ": cannot write");
  });
}

void writePly(const fs::path& path, const TriangleMesh& mesh, const std::vector<float>* variance,
              const std::vector<std::array<uint8_t, 4>>* rgba) {
  if (variance && variance->size() != mesh.vertices.size())
    throw Error(path.string() + ": variance count does not match vertex count");
  if (rgba && rgba->size() != mesh.vertices.size())
    throw Error(path.string() + ": colour count does not match vertex count");
  writeFileAtomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw Error(path.string() + ": cannot open for writing");
    out << "ply\nformat binary_little_endian 1.0\ncomment written by inhand; units: metres\n";
    out << "element vertex " << mesh.vertices.size() << "\n";
    out << "property float x\nproperty float y\nproperty float z\n";
    if (variance) {
      out << "comment variance: per-vertex surface variance in m^2 (sigma = 5 cm: never "
             "observed)\n";
      out << "property float variance\n";
    }
    if (rgba)
      out << "comment red, green, blue: the scanned colour (sRGB); alpha 0 where no colour was "
             "observed\n";
    if (variance || rgba) out << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    if (rgba) out << "property uchar alpha\n";
    out << "element face " << mesh.triangles.size() << "\n";
    out << "property list uchar int vertex_indices\nend_header\n";
    const size_t stride = 12 + (variance ? 4 : 0) + (rgba ? 4 : variance ? 3 : 0);
    std::vector<char> buf(mesh.vertices.size() * stride);
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      char* p = buf.data() + i * stride;
      std::memcpy(p, mesh.vertices[i].data(), 12);
      p += 12;
      if (variance) {
        float v = (*variance)[i];
        std::memcpy(p, &v, 4);
        p += 4;
      }
      if (rgba) {
        std::memcpy(p, (*rgba)[i].data(), 4);
      } else if (variance) {
        auto c = confidenceColor((*variance)[i]);
        std::memcpy(p, c.data(), 3);
      }
    }
    out.write(buf.data(), std::streamsize(buf.size()));
    std::vector<char> fbuf(mesh.triangles.size() * 13);
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      char* p = fbuf.data() + t * 13;
      p[0] = 3;
      std::memcpy(p + 1, mesh.triangles[t].data(), 12);
    }
    out.write(fbuf.data(), std::streamsize(fbuf.size()));
    out.close();
    if (!out) throw Error(path.string() + ": write failed (disk full?)");
  });
}

namespace {

// A value's type in the body, resolved from its name once (typeOf).
enum class PlyType : uint8_t {
  kNone,
  kInt8,
  kUint8,
  kInt16,
  kUint16,
  kInt32,
  kUint32,
  kFloat,
  kDouble
};

struct PlyProperty {
  std::string name, type, countType;  // countType non-empty for list properties
  PlyType kind = PlyType::kNone, countKind = PlyType::kNone;
};
struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> props;
};

PlyType typeOf(const std::string& t) {
  if (t == "char" || t == "int8") return PlyType::kInt8;
  if (t == "uchar" || t == "uint8") return PlyType::kUint8;
  if (t == "short" || t == "int16") return PlyType::kInt16;
  if (t == "ushort" || t == "uint16") return PlyType::kUint16;
  if (t == "int" || t == "int32") return PlyType::kInt32;
  if (t == "uint" || t == "uint32") return PlyType::kUint32;
  if (t == "float" || t == "float32") return PlyType::kFloat;
  if (t == "double" || t == "float64") return PlyType::kDouble;
  return PlyType::kNone;
}

int sizeOf(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUint8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUint16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat:
      return 4;
    case PlyType::kDouble:
      return 8;
    default:
      return 0;
  }
}

double decode(const char* p, PlyType t, bool bigEndian) {
  auto get = [&](auto v) {
    char bytes[sizeof(v)];
    std::memcpy(bytes, p, sizeof(v));
    if (bigEndian) std::reverse(bytes, bytes + sizeof(v));
    std::memcpy(&v, bytes, sizeof(v));
    return double(v);
  };
  switch (t) {
    case PlyType::kInt8:
      return get(int8_t{});
    case PlyType::kUint8:
      return get(uint8_t{});
    case PlyType::kInt16:
      return get(int16_t{});
    case PlyType::kUint16:
      return get(uint16_t{});
    case PlyType::kInt32:
      return get(int32_t{});
    case PlyType::kUint32:
      return get(uint32_t{});
    case PlyType::kFloat:
      return get(float{});
    default:
      return get(double{});
  }
}

}  // namespace

namespace {
// A PLY file's header: its format, its elements with their properties, where the body starts.
struct PlyHeader {
  std::string format;
  std::vector<PlyElement> elements;
  size_t bodyStart = 0;
};
PlyHeader readPlyHeader(const std::string& data, const std::string& where) {
  size_t headerEnd = data.find("end_header");
  if (data.rfind("ply", 0) != 0 || headerEnd == std::string::npos)
    throw Error(where + ": not a PLY file (no 'ply' magic or 'end_header')");
  size_t bodyStart = data.find('\n', headerEnd);
  if (bodyStart == std::string::npos) throw Error(where + ": PLY header is not terminated");
  ++bodyStart;
  std::istringstream header(data.substr(0, headerEnd));
  std::string line, format;
  std::vector<PlyElement> elements;
  while (std::getline(header, line)) {
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "format") {
      ls >> format;
    } else if (word == "element") {
      PlyElement e;
      ls >> e.name >> e.count;
      if (!ls) throw Error(where + ": malformed PLY element line '" + line + "'");
      elements.push_back(e);
    } else if (word == "property") {
      if (elements.empty()) throw Error(where + ": PLY property before any element");
      PlyProperty p;
      ls >> p.type;
      if (p.type == "list") ls >> p.countType >> p.type;
      ls >> p.name;
      p.kind = typeOf(p.type);
      if (!p.countType.empty()) p.countKind = typeOf(p.countType);
      if (!ls || p.kind == PlyType::kNone ||
          (!p.countType.empty() && p.countKind == PlyType::kNone))
        throw Error(where + ": unsupported PLY property line '" + line + "'");
      elements.back().props.push_back(p);
    }
  }
  if (format != "binary_little_endian" && format != "binary_big_endian" && format != "ascii")
    throw Error(where + ": PLY format '" + format +
                "' is not supported (ascii, binary_little_endian, binary_big_endian)");
  return {format, elements, bodyStart};
}
}  // namespace

namespace {
// Where each property's values go, decided once per element: a coordinate (0-2), a vertex
// property's values (in out), a face's indices, or nowhere.
struct PlyTarget {
  int coordinate = -1;
  std::vector<float>* values = nullptr;
  bool indices = false;
};
std::vector<PlyTarget> plyTargets(const PlyElement& e, PlyData* out) {
  const bool isVertex = e.name == "vertex", isFace = e.name == "face";
  std::vector<PlyTarget> targets(e.props.size());
  for (size_t k = 0; k < e.props.size() && e.count > 0; ++k) {
    const PlyProperty& p = e.props[k];
    PlyTarget& t = targets[k];
    if (!p.countType.empty()) {
      t.indices = isFace && (p.name == "vertex_indices" || p.name == "vertex_index");
    } else if (isVertex) {
      if (p.name == "x")
        t.coordinate = 0;
      else if (p.name == "y")
        t.coordinate = 1;
      else if (p.name == "z")
        t.coordinate = 2;
      else
        t.values = &out->vertexProperties[p.name];
    }
  }
  return targets;
}
}  // namespace

PlyData readPly(const fs::path& path) {
  std::string data = readTextFile(path);
  const std::string where = path.string();
  const auto [format, elements, bodyStart] = readPlyHeader(data, where);
  const bool ascii = format == "ascii", bigEndian = format == "binary_big_endian";
  PlyData out;
  size_t pos = bodyStart;
  std::istringstream text(ascii ? data.substr(bodyStart) : std::string());
  auto readValue = [&](PlyType type) -> double {
    if (ascii) {
      double v;
      if (!(text >> v)) throw Error(where + ": PLY body ends early or has a non-number");
      return v;
    }
    const int n = sizeOf(type);
    if (pos + size_t(n) > data.size()) throw Error(where + ": PLY body is truncated");
    double v = decode(data.data() + pos, type, bigEndian);
    pos += size_t(n);
    return v;
  };
  // Every value takes at least a byte of the body: a count beyond that is a lie (a header that
  // claims 10^9 vertices is an error, not an allocation).
  const size_t bodyBytes = data.size() - std::min(bodyStart, data.size());
  auto index = [&](double value, const char* what) {
    if (!(value >= 0 && value <= double(std::numeric_limits<int>::max())) ||
        value != std::floor(value))
      throw Error(where + ": PLY " + what + " " + std::to_string(value) +
                  " is not a non-negative integer");
    return int(value);
  };
  std::vector<int> idx;  // one face's indices
  for (const PlyElement& e : elements) {
    const bool isVertex = e.name == "vertex";
    if (e.props.empty()) continue;  // nothing to read
    if (e.count > bodyBytes)
      throw Error(where + ": PLY element '" + e.name + "' claims " + std::to_string(e.count) +
                  " entries, more than the file's " + std::to_string(bodyBytes) + " body bytes");
    const std::vector<PlyTarget> targets = plyTargets(e, &out);
    for (size_t i = 0; i < e.count; ++i) {
      Vec3f v = Vec3f::Zero();
      for (size_t k = 0; k < e.props.size(); ++k) {
        const PlyProperty& p = e.props[k];
        const PlyTarget& t = targets[k];
        if (p.countKind != PlyType::kNone) {
          const int n = index(readValue(p.countKind), "list length");
          if (size_t(n) > bodyBytes)
            throw Error(where + ": PLY list of " + std::to_string(n) +
                        " values is longer than the file");
          idx.assign(size_t(n), 0);
          for (int j = 0; j < n; ++j) {
            const double value = readValue(p.kind);
            if (t.indices) idx[size_t(j)] = index(value, "vertex index");
          }
          if (t.indices)
            for (int j = 1; j + 1 < n; ++j)
              out.mesh.triangles.emplace_back(idx[0], idx[size_t(j)], idx[size_t(j) + 1]);
          continue;
        }
        const double value = readValue(p.kind);
        if (t.coordinate >= 0)
          v[t.coordinate] = float(value);
        else if (t.values)
          t.values->push_back(float(value));
      }
      if (isVertex) out.mesh.vertices.push_back(v);
    }
  }
  std::string problem = validateMesh(out.mesh);
  if (!problem.empty()) throw Error(where + ": mesh " + problem);
  return out;
}

}  // namespace inhand

namespace inhand {

namespace {
// The materials of an MTL file: `newmtl`, `Kd r g b` (0–1) and `map_Kd FILE` (PNG or JPEG,
// relative to the MTL's folder; options before the file name are not read). Errors name the file
// and line.
std::vector<Material> readMtl(const fs::path& path) {
  const std::string data = readTextFile(path);
  std::vector<Material> out;
  std::istringstream in(data);
  std::string line;
  int lineNo = 0;
  while (std::getline(in, line)) {
    ++lineNo;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string key;
    if (!(ls >> key)) continue;
    auto fail = [&](const std::string& what) {
      return Error(path.string() + ": line " + std::to_string(lineNo) + ": " + what);
    };
    if (key == "newmtl") {
      Material m;
      std::getline(ls >> std::ws, m.name);
      out.push_back(std::move(m));
    } else if (key == "Kd" || key == "map_Kd") {
      if (out.empty()) throw fail(key + " before any newmtl");
      if (key == "Kd") {
        double c[3];
        for (double& x : c)
          if (!(ls >> x) || !(x >= 0 && x <= 1)) throw fail("Kd needs three numbers in [0, 1]");
        for (int k = 0; k < 3; ++k)
          out.back().diffuse[size_t(k)] = uint8_t(std::lround(255 * c[k]));
      } else {
        std::string file;
        std::getline(ls >> std::ws, file);
        out.back().texture = readRgbImage(path.parent_path() / file);
      }
    }
  }
  return out;
}
}  // namespace

TexturedMesh importTexturedMesh(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  TexturedMesh out;
  std::error_code ec;
  if (ext == ".obj" && fs::is_regular_file(path, ec)) {
    ObjColours oc;
    TriangleMesh mesh = readObj(path, &oc);
    if (std::string problem = validateMesh(mesh); !problem.empty())
      throw Error(path.string() + ": mesh " + problem);
    std::vector<Material> library;
    for (const std::string& lib : oc.mtllibs)
      for (Material& m : readMtl(path.parent_path() / lib)) library.push_back(std::move(m));
    SurfaceColours& c = out.colours;
    for (const std::string& name : oc.material_names) {
      auto it = std::find_if(library.begin(), library.end(),
                             [&](const Material& m) { return m.name == name; });
      if (it == library.end())
        throw Error(path.string() + ": material " + name + " is in no mtllib it names");
      c.materials.push_back(*it);
    }
    c.triangle_material = oc.triangle_material;
    bool anyUv = false;
    for (int t : oc.corner_vt) anyUv |= t >= 0;
    if (anyUv)
      for (int t : oc.corner_vt) c.corner_uv.push_back(t >= 0 ? oc.vt[size_t(t)] : Vec2f(0, 0));
    std::vector<int> kept;
    out.mesh = welded(mesh, 1e-7, &kept);
    out.colours = c.withTriangles(kept);
    return out;
  }
  if (ext == ".ply" && fs::is_regular_file(path, ec)) {
    PlyData ply = readPly(path);
    std::vector<int> kept, remap;
    out.mesh = welded(ply.mesh, 1e-7, &kept, &remap);
    const auto& p = ply.vertexProperties;
    if (p.count("red") && p.count("green") && p.count("blue")) {
      const std::vector<float>* ch[3] = {&p.at("red"), &p.at("green"), &p.at("blue")};
      out.colours.vertex_rgb.assign(out.mesh.vertices.size(), {0, 0, 0});
      // The first of the vertices welded into one gives its colour.
      std::vector<uint8_t> set(out.mesh.vertices.size(), 0);
      for (size_t i = 0; i < remap.size() && i < ch[0]->size(); ++i) {
        const size_t j = size_t(remap[i]);
        if (set[j]++) continue;
        for (int k = 0; k < 3; ++k)
          out.colours.vertex_rgb[j][size_t(k)] =
              uint8_t(std::clamp(std::lround((*ch[k])[i]), 0L, 255L));
      }
    }
    return out;
  }
  out.mesh = importMesh(path);
  return out;
}

}  // namespace inhand
