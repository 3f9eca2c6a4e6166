#pragma once
#include <array>
// S_obj of Alg. 1: one closed surface from the TsdfVolume (paper §III-B). The scalar field is the
// fused signed distance on observed voxels, +μ on empty voxels and −μ on unknown voxels (and +μ
// on a one-voxel border around the grid, so the surface closes at the volume's edge). Its zero
// set is the maximum-likelihood surface where measured, extended over the empty/unknown boundary
// elsewhere. Vertex variance: 1/Σw interpolated between observed voxels; σ = hole_sigma_m
// (5 cm) for vertices on an edge touching an unknown voxel (never observed); a surface-nets
// vertex is a hole vertex if any crossing of its cube is, else it takes their mean variance.
#include <string>
#include <vector>

#include "inhand/core/options.h"
#include "inhand/geometry/triangle_mesh.h"
#include "inhand/volume/tsdf_volume.h"

namespace inhand {

// How the zero set becomes triangles (geometry/contour.h): marching tetrahedra (watertight, dense:
// the model written out) or surface nets (about a fifth of the triangles: planning).
enum class SurfaceMethod { kTetrahedra, kSurfaceNets };
inline constexpr EnumNames<SurfaceMethod, 2> kSurfaceMethodNames = {
    {SurfaceMethod::kTetrahedra, "tetrahedra"}, {SurfaceMethod::kSurfaceNets, "surface_nets"}};
std::string surfaceMethodName(SurfaceMethod m);  // "tetrahedra" | "surface_nets"
bool parseSurfaceMethod(const std::string& s, SurfaceMethod* out);

struct MeshOptions {
  double hole_sigma_m = 0.05;  // σ assigned to hole-filling (empty/unknown boundary) vertices, m
  // Treat unknown regions (6-connected) that touch no observed voxel as empty: pockets of free
  // space that no ray happened to cross (e.g. seen only against no-return background) carry no
  // evidence of a surface, and the held object is one connected body.
  bool drop_floating_unknown = true;
  // Drop connected surface pieces with fewer triangles than this fraction of the largest piece
  // (specks from flying pixels at depth edges); 0 keeps everything.
  double min_component_fraction = 0.01;
  // Use every stride-th voxel along each axis (1: full resolution). Planning can use a coarser
  // S_obj than the model written out.
  int stride = 1;
  SurfaceMethod method = SurfaceMethod::kTetrahedra;

  template <class V, class S>
  static void fields(V& v, S& o) {
    v.num("hole_sigma_m", o.hole_sigma_m, "σ of never-observed (hole-filled) surface, m",
          Range::above(0));
    v.boolean("drop_floating_unknown", o.drop_floating_unknown,
              "drop components with no observed vertex");
    v.num("min_component_fraction", o.min_component_fraction,
          "drop components smaller than this fraction of the largest", Range::closed(0, 1));
    v.integer("stride", o.stride, "every n-th voxel along each axis", Range::closed(1, 8));
    v.choice("method", o.method, kSurfaceMethodNames,
             "marching tetrahedra (watertight) or surface nets (a fifth of the triangles)");
  }
  std::string validate() const;
};

// Marks (1) the unknown voxels 6-connected through unknown voxels to an observed voxel (what
// MeshOptions::drop_floating_unknown keeps): the unknown voxels as runs along x, flooded run by
// run. The reference floods voxel by voxel; both give the same marks.
std::vector<uint8_t> unknownAttachedToObserved(const TsdfVolume& volume);
std::vector<uint8_t> unknownAttachedToObservedReference(const TsdfVolume& volume);

struct ObjectModel {
  TriangleMesh mesh;              // object frame O, outward-oriented
  std::vector<float> variance;    // per vertex, m²
  std::vector<uint8_t> observed;  // per vertex: 1 from measurements, 0 hole-filled
  // Per vertex, when the scan had colour: sRGB and alpha (255: colour seen there, 0: none).
  std::vector<std::array<uint8_t, 4>> rgba;

  // Paper Fig. 5: mean over vertices of ½ ln(2πe σ²), nats.
  double meanEntropy() const;
  // Area fraction of triangles whose three vertices are observed.
  double observedAreaFraction() const;
  // ∫ max(0, ½ ln(σ²/σ_ref²)) dA over the surface (σ² interpolated linearly over each triangle
  // from its corners, by the mean of the corners' logs), nats·m²: what eq. 9 could still gain if
  // every point were measured once with σ_ref.
  double unresolvedInformation(double sigma_ref_m) const;
  // Area (m²) of triangles with at least one hole-filled vertex.
  double holeArea() const;
  // The measured surface alone: the triangles whose three vertices are observed (an open mesh,
  // as other fusion tools give), unused vertices dropped.
  ObjectModel observedSurface() const;
};

ObjectModel extractModel(const TsdfVolume& volume, const MeshOptions& options = {});

// ½ ln(2πe σ²) for a Gaussian of variance σ² (nats).
double gaussianEntropy(double variance);

}  // namespace inhand
