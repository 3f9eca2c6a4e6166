// The scanned object as an asset: mass and inertia against analytic solids, the written MJCF,
// URDF and SDF as MuJoCo, urdfdom and libsdformat read them, and an exported cup dropped on a
// table in MuJoCo.
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>
#include <urdf_parser/urdf_parser.h>
#include <Eigen/Eigenvalues>
#include <sdf/Link.hh>
#include <sdf/Model.hh>
#include <sdf/Root.hh>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <set>

#include "inhand/asset/asset.h"
#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/geometry/primitives.h"
#include "inhand/geometry/stable_poses.h"
#include "test_util.h"

using namespace inhand;

namespace {

struct Expected {
  double volume;
  Vec3 principal;  // principal moments per kg/m³ of density (x, y, z of the solid's frame)
};

// A torus about z: major radius R, tube radius r (marching cubes of its distance field).
TriangleMesh torus(double R, double r) {
  auto f = [&](const Vec3& p) { return std::hypot(std::hypot(p.x(), p.y()) - R, p.z()) - r; };
  Aabb b;
  b.extend(Vec3(-(R + r + 0.01), -(R + r + 0.01), -(r + 0.01)));
  b.extend(Vec3(R + r + 0.01, R + r + 0.01, r + 0.01));
  return meshImplicit(f, b, 0.001);
}

// A cup: 80 mm across, 95 mm tall, 4 mm wall and 5 mm bottom, as a closed solid of revolution.
TriangleMesh cup() {
  return makeRevolution(
      {{0, 0}, {0.040, 0}, {0.040, 0.095}, {0.036, 0.095}, {0.036, 0.005}, {0, 0.005}}, 64);
}

fs::path freshDir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("inhand_asset_" + name);
  fs::remove_all(d);
  return d;
}

void expectSolid(const TriangleMesh& mesh, const Expected& e, double tol) {
  AssetOptions o;
  o.density_kg_m3 = 500;
  const ObjectAsset a = makeAsset(mesh, o);
  EXPECT_NEAR(a.volume_m3, e.volume, tol * e.volume);
  EXPECT_NEAR(a.mass_kg, 500 * e.volume, tol * 500 * e.volume);
  EXPECT_LT(a.com_O.norm(), 1e-3);
  for (int k = 0; k < 3; ++k)
    EXPECT_NEAR(a.inertia_kg_m2(k, k), 500 * e.principal[k], tol * 500 * e.principal[k]) << k;
  EXPECT_LT(std::abs(a.inertia_kg_m2(0, 1)), 0.01 * a.inertia_kg_m2(0, 0));
  // The collision pieces cover the solid, exceeding it by little (the decomposition's excess).
  EXPECT_GE(a.pieces_volume_m3, (1 - tol) * e.volume);
  EXPECT_LE(a.pieces_volume_m3, 1.06 * e.volume);
}

}  // namespace

TEST(Asset, MassAndInertiaOfABoxACylinderAndATorusAreTheAnalyticOnes) {
  const double a = 0.10, b = 0.06, c = 0.20;
  const double vb = a * b * c;
  expectSolid(
      makeBox(Vec3(a, b, c)),
      {vb, Vec3(vb * (b * b + c * c) / 12, vb * (a * a + c * c) / 12, vb * (a * a + b * b) / 12)},
      1e-6);
  const double r = 0.03, h = 0.12, vc = M_PI * r * r * h;
  expectSolid(
      makeCylinder(r, h, 128),
      {vc, Vec3(vc * (3 * r * r + h * h) / 12, vc * (3 * r * r + h * h) / 12, vc * r * r / 2)},
      0.01);
  const double R = 0.05, t = 0.015, vt = 2 * M_PI * M_PI * R * t * t;
  expectSolid(torus(R, t),
              {vt, Vec3(vt * (R * R / 2 + 5 * t * t / 8), vt * (R * R / 2 + 5 * t * t / 8),
                        vt * (R * R + 3 * t * t / 4))},
              0.03);
}

TEST(Asset, InwardTrianglesAreTheSameSolidAndAnOpenSheetIsRefused) {
  TriangleMesh box = makeBox(Vec3(0.1, 0.1, 0.1));
  for (Tri& t : box.triangles) std::swap(t[1], t[2]);
  EXPECT_NEAR(makeAsset(box, {}).volume_m3, 1e-3, 1e-9);
  TriangleMesh sheet;
  sheet.vertices = {Vec3f(0, 0, 0), Vec3f(0.1f, 0, 0), Vec3f(0, 0.1f, 0)};
  sheet.triangles = {Tri(0, 1, 2)};
  EXPECT_THROW(makeAsset(sheet, {}), Error);
  AssetOptions bad;
  bad.name = "my object";
  EXPECT_THROW(makeAsset(box, bad), Error);
}

TEST(Asset, WrittenMjcfAndUrdfLoadInMujocoAndUrdfdomWithTheAssetsInertia) {
  AssetOptions o;
  o.name = "part";
  o.mass_kg = 0.35;
  const ObjectAsset a = makeAsset(cup(), o);
  EXPECT_NEAR(a.density_kg_m3 * a.volume_m3, 0.35, 1e-9);
  const fs::path dir = freshDir("cup");
  writeAsset(a, dir, {AssetFormat::kMjcf, AssetFormat::kUrdf, AssetFormat::kSdf});
  for (const char* f : {"part.xml", "part.urdf", "part.sdf", "visual.stl", "collision_000.stl",
                        "model.ply", "asset.json", "grasps.json"})
    EXPECT_TRUE(fs::exists(dir / f)) << f;
  // The pieces as written: binary STL read back, each convex, their volumes the decomposition's.
  for (size_t i = 0; i < a.pieces.size(); ++i) {
    char name[48];
    std::snprintf(name, sizeof name, "collision_%03zu.stl", i % 1000);
    const TriangleMesh piece = importMesh(dir / name);
    EXPECT_NEAR(massProperties(piece).volume_m3, a.pieces[i].volume_m3,
                1e-4 * a.pieces[i].volume_m3 + 1e-12);
  }
  // urdfdom: one link with the mass, inertia and every collision piece.
  const urdf::ModelInterfaceSharedPtr u = urdf::parseURDF(readTextFile(dir / "part.urdf"));
  ASSERT_TRUE(u);
  const auto link = u->getLink("part");
  ASSERT_TRUE(link && link->inertial);
  EXPECT_NEAR(link->inertial->mass, 0.35, 1e-6);
  EXPECT_NEAR(link->inertial->izz, a.inertia_kg_m2(2, 2), 1e-6 * a.inertia_kg_m2(2, 2));
  EXPECT_EQ(link->collision_array.size(), a.pieces.size());
  // libsdformat (Gazebo's parser): no error; the link's mass, inertia, centre of mass, pieces.
  sdf::Root root;
  const sdf::Errors errors = root.Load((dir / "part.sdf").string());
  EXPECT_TRUE(errors.empty()) << (errors.empty() ? "" : errors.front().Message());
  const sdf::Link* sdfLink = root.Model() ? root.Model()->LinkByName("part") : nullptr;
  ASSERT_TRUE(sdfLink);
  const auto& inertial = sdfLink->Inertial();
  EXPECT_NEAR(inertial.MassMatrix().Mass(), 0.35, 1e-6);
  EXPECT_NEAR(inertial.MassMatrix().Izz(), a.inertia_kg_m2(2, 2), 1e-6 * a.inertia_kg_m2(2, 2));
  EXPECT_NEAR(inertial.MassMatrix().Ixy(), a.inertia_kg_m2(0, 1), 1e-6 * a.inertia_kg_m2(2, 2));
  const auto& com = inertial.Pose().Pos();
  EXPECT_NEAR((Vec3(com.X(), com.Y(), com.Z()) - a.com_O).norm(), 0, 1e-6);
  EXPECT_EQ(sdfLink->CollisionCount(), a.pieces.size());
  EXPECT_EQ(sdfLink->VisualCount(), 1u);
  // MuJoCo: the MJCF and the URDF compile to a body of that mass; its principal moments and
  // centre of mass are the asset's.
  for (const char* f : {"part.xml", "part.urdf"}) {
    char error[1000] = "";
    mjModel* m = mj_loadXML((dir / f).string().c_str(), nullptr, error, sizeof error);
    ASSERT_TRUE(m) << f << ": " << error;
    const int body = mj_name2id(m, mjOBJ_BODY, "part");
    ASSERT_GE(body, 0) << f;
    EXPECT_NEAR(m->body_mass[body], 0.35, 1e-6) << f;
    Eigen::SelfAdjointEigenSolver<Mat3> es(a.inertia_kg_m2);
    std::vector<double> mine{es.eigenvalues()[0], es.eigenvalues()[1], es.eigenvalues()[2]};
    std::vector<double> theirs{m->body_inertia[3 * body], m->body_inertia[3 * body + 1],
                               m->body_inertia[3 * body + 2]};
    std::sort(theirs.begin(), theirs.end());
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(theirs[k], mine[k], 1e-4 * mine[k]) << f;
    EXPECT_NEAR(
        (Vec3(m->body_ipos[3 * body], m->body_ipos[3 * body + 1], m->body_ipos[3 * body + 2]) -
         a.com_O)
            .norm(),
        0, 1e-6)
        << f;
    mj_deleteModel(m);
  }
  fs::remove_all(dir);
}

TEST(Asset, AnExportedCupDroppedOnATableComesToRestInOneOfItsStablePoses) {
  const TriangleMesh mesh = cup();
  const std::vector<StablePose> poses = stablePoses(mesh);
  ASSERT_FALSE(poses.empty());
  AssetOptions o;
  o.name = "cup";
  const ObjectAsset a = makeAsset(mesh, o);
  const fs::path dir = freshDir("drop");
  writeAsset(a, dir, {AssetFormat::kMjcf});
  // A scene a user would write: the asset included, a floor under it.
  writeTextAtomically(dir / "scene.xml",
                      "<mujoco><include file=\"cup.xml\"/><option timestep=\"0.002\"/>"
                      "<worldbody><geom name=\"floor\" type=\"plane\" size=\"1 1 0.01\"/>"
                      "</worldbody></mujoco>");
  char error[1000] = "";
  mjModel* m = mj_loadXML((dir / "scene.xml").string().c_str(), nullptr, error, sizeof error);
  ASSERT_TRUE(m) << error;
  mjData* d = mj_makeData(m);
  // Dropped from 15 cm in six orientations: each comes to rest in a stable pose of the true mesh.
  const std::vector<std::pair<double, Vec3>> drops{{0.4, Vec3(1, 0, 0)}, {1.3, Vec3(0, 1, 0)},
                                                   {2.0, Vec3(1, 1, 0)}, {2.8, Vec3(1, 0, 1)},
                                                   {3.1, Vec3(0, 1, 1)}, {0.9, Vec3(1, 1, 1)}};
  int rested = 0;
  std::set<int> kinds;
  for (int trial = 0; trial < int(drops.size()); ++trial) {
    mj_resetData(m, d);
    const Eigen::Quaterniond q(
        Eigen::AngleAxisd(drops[size_t(trial)].first, drops[size_t(trial)].second.normalized()));
    d->qpos[2] = 0.15;
    d->qpos[3] = q.w(), d->qpos[4] = q.x(), d->qpos[5] = q.y(), d->qpos[6] = q.z();
    for (int step = 0; step < 2500; ++step) mj_step(m, d);
    const Eigen::Quaterniond r(d->qpos[3], d->qpos[4], d->qpos[5], d->qpos[6]);
    const Vec3 down_O = r.toRotationMatrix().transpose() * Vec3(0, 0, -1);
    // The cup's poses by its axis (z): standing (down −z), upside down (+z), on its side (⟂ z;
    // stablePoses gives the side's facets as one pose). The pose it came to rest in must be one
    // of stablePoses', at that pose's height of the centre of mass.
    auto kind = [](const Vec3& down) {
      return down.z() < -0.996 ? 0 : down.z() > 0.996 ? 1 : std::abs(down.z()) < 0.087 ? 2 : 3;
    };
    const double height = d->xipos[3 * mj_name2id(m, mjOBJ_BODY, "cup") + 2];
    double best = 1;  // metres off the matching pose's height
    for (const StablePose& p : poses)
      if (kind(p.down_O) == kind(down_O)) best = std::min(best, std::abs(p.height_m - height));
    const double speed = Vec3(d->qvel[0], d->qvel[1], d->qvel[2]).norm();
    EXPECT_LT(kind(down_O), 3) << "trial " << trial;
    EXPECT_LT(best, 0.002) << "trial " << trial;
    EXPECT_LT(speed, 0.01) << "trial " << trial;
    rested += kind(down_O) < 3 && best < 0.002;
    kinds.insert(kind(down_O));
  }
  EXPECT_EQ(rested, int(drops.size()));
  EXPECT_GE(kinds.size(), 2u);  // not every drop lands standing
  mj_deleteData(d);
  mj_deleteModel(m);
  fs::remove_all(dir);
}

TEST(Asset, AnAssetThatCannotBeWrittenLeavesNoDirectory) {
  const ObjectAsset a = makeAsset(makeBox(Vec3(0.05, 0.05, 0.05)), {});
  const fs::path dir = freshDir("full");
  fs::create_directories(dir);
  { std::ofstream(dir / "something") << "x"; }
  EXPECT_THROW(writeAsset(a, dir, {AssetFormat::kMjcf}), Error);  // not empty
  EXPECT_TRUE(fs::exists(dir / "something"));
  fs::remove_all(dir);
  EXPECT_EQ(assetFormatFromName("gltf"), std::nullopt);
  EXPECT_EQ(*assetFormatFromName("urdf"), AssetFormat::kUrdf);
}
