#pragma once
// The scanned object as an asset for simulators and planners: its visual mesh, collision
// geometry as convex pieces of the closed model (the decomposition the simulator's physics uses),
// mass and inertia of the solid the model encloses, and a grasp set; written as MJCF (MuJoCo),
// URDF and SDF. Everything is in the model's frame O, metres and kilograms.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "inhand/core/json_util.h"
#include "inhand/geometry/convex_decomposition.h"

namespace inhand {

struct AssetOptions {
  std::string name = "object";  // the body's (link's, model's) name: [A-Za-z0-9_-], ≤ 64
  double density_kg_m3 = 300;   // of the enclosed solid (YCB objects: about 100–1000)
  double mass_kg = 0;           // > 0: this mass (the density follows from it)
  // The visual mesh for simulators is simplified (vertex clustering) to at most this many
  // triangles (MuJoCo reads STL files of at most 200000); the full model is copied beside it.
  int max_visual_triangles = 100000;
  ConvexDecompositionOptions decomposition;
  std::string validate() const;
};

struct ObjectAsset {
  std::string name;
  TriangleMesh model_O;             // the closed model, outward triangles
  TriangleMesh visual_O;            // model_O simplified to max_visual_triangles
  std::vector<ConvexPiece> pieces;  // collision geometry
  double volume_m3 = 0;             // the closed model's enclosed volume
  double pieces_volume_m3 = 0;  // the pieces' hulls (≥ volume_m3 by the decomposition's excess)
  double density_kg_m3 = 0;
  double mass_kg = 0;
  Vec3 com_O = Vec3::Zero();          // centre of mass
  Mat3 inertia_kg_m2 = Mat3::Zero();  // about the centre of mass, axes of O
  Json grasps = Json::array();        // the grasp set (see docs/asset.md)
};

// The asset of a closed model (a mesh whose triangles all face inwards is turned outwards).
// Throws Error when the model encloses no volume or the options are invalid.
ObjectAsset makeAsset(const TriangleMesh& closed_O, const AssetOptions& options);

enum class AssetFormat { kMjcf, kUrdf, kSdf };
// "mjcf", "urdf", "sdf"; nullopt for anything else.
std::optional<AssetFormat> assetFormatFromName(const std::string& name);
const char* assetFormatName(AssetFormat format);

// The model files' text (the meshes they name are written by writeAsset beside them).
std::string mjcfText(const ObjectAsset& asset);
std::string urdfText(const ObjectAsset& asset);
std::string sdfText(const ObjectAsset& asset);

// Writes the asset into `dir` (new, or an empty directory), whole or not at all: NAME.xml,
// NAME.urdf, NAME.sdf (those of `formats`), visual.stl, collision_NNN.stl, model.ply (the full
// model; `model_ply` is copied when given, colours and variance included, else model_O is
// written), asset.json and grasps.json. Before the directory appears, the MJCF is compiled by
// MuJoCo and the URDF parsed by urdfdom (and compiled by MuJoCo); a refusal throws Error.
void writeAsset(const ObjectAsset& asset, const std::filesystem::path& dir,
                const std::vector<AssetFormat>& formats,
                const std::optional<std::filesystem::path>& model_ply = std::nullopt);

// What a robot needs of an asset directory to find and pick up the object again.
struct LoadedAsset {
  std::string name;
  TriangleMesh model_O;           // model.ply: the closed model
  std::vector<uint8_t> observed;  // per vertex: 1 measured, 0 hole-filled (variance of σ 5 cm)
  double mass_kg = 0;             // asset.json
  Vec3 com_O = Vec3::Zero();      // asset.json
  Json grasps = Json::array();    // grasps.json
};
// Reads `dir` as writeAsset wrote it. Throws Error naming the file and what is wrong.
LoadedAsset readAsset(const std::filesystem::path& dir);

// The body's mass (kg) as MuJoCo compiles a model file (MJCF or URDF) whose body is named
// `body`; throws Error with MuJoCo's message when it refuses the file or has no such body.
double mujocoBodyMass(const std::filesystem::path& model_file, const std::string& body);

}  // namespace inhand
