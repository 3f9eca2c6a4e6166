#include "inhand/robot/collision.h"

#include <fcl/fcl.h>

#include <limits>
#include <map>
#include <optional>
#include <set>

#include "inhand/core/error.h"
#include "inhand/geometry/internal/box_overlap.h"
#include "inhand/geometry/primitives.h"

namespace inhand {

namespace {

using GeomPtr = std::shared_ptr<fcl::CollisionGeometryd>;

GeomPtr bvhOf(const TriangleMesh& mesh) {
  auto model = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  std::vector<fcl::Vector3d> v;
  v.reserve(mesh.vertices.size());
  for (const Vec3f& p : mesh.vertices) v.push_back(p.cast<double>());
  std::vector<fcl::Triangle> t;
  t.reserve(mesh.triangles.size());
  for (const Tri& f : mesh.triangles) t.emplace_back(size_t(f[0]), size_t(f[1]), size_t(f[2]));
  model->beginModel();
  model->addSubModel(v, t);
  model->endModel();
  return model;
}

GeomPtr fclOf(const Primitive& p) {
  switch (p.type) {
    case Primitive::Type::kBox:
      return std::make_shared<fcl::Boxd>(p.size.x(), p.size.y(), p.size.z());
    case Primitive::Type::kCylinder:
      return std::make_shared<fcl::Cylinderd>(p.size.x(), p.size.z());
    case Primitive::Type::kSphere:
      return std::make_shared<fcl::Sphered>(p.size.x());
    case Primitive::Type::kMesh:
      return bvhOf(*p.mesh);
  }
  return nullptr;
}

struct Part {
  int link;
  GeomPtr geom;
  Iso3 T_link_geom;
};

bool collide(const GeomPtr& a, const Iso3& Ta, const GeomPtr& b, const Iso3& Tb) {
  // The geometry-level call: a CollisionObject would recompute its geometry's local AABB on
  // construction, a pass over every vertex (half the time of a grasp generation on a 100 k
  // vertex model before this).
  fcl::CollisionRequestd req;
  fcl::CollisionResultd res;
  fcl::collide(a.get(), fcl::Transform3d(Ta.matrix()), b.get(), fcl::Transform3d(Tb.matrix()), req,
               res);
  return res.isCollision();
}

}  // namespace

struct CollisionChecker::Impl {
  const RobotModel* model;
  std::vector<Part> moving, fixed;  // fixed: links that no joint moves (the robot's base)
  GeomPtr table;
  GeomPtr held;
  Iso3 T_tip_held = Iso3::Identity();
  std::set<int> adjacent;
};

CollisionChecker::CollisionChecker(const RobotModel& model) : impl_(std::make_unique<Impl>()) {
  impl_->model = &model;
  // A link is static when no movable joint lies between it and the root.
  std::vector<int> isStatic(model.links().size(), 1);
  for (int li = 0; li < int(model.links().size()); ++li)
    for (int ji = model.links()[li].parentJoint; ji >= 0;
         ji = model.links()[model.joints()[ji].parentLink].parentJoint)
      if (model.joints()[ji].variable >= 0) {
        isStatic[li] = 0;
        break;
      }
  for (int li = 0; li < int(model.links().size()); ++li)
    for (const Primitive& p : model.links()[li].collision)
      (isStatic[li] ? impl_->fixed : impl_->moving).push_back({li, fclOf(p), p.T_link_geom});
  const TableInfo& t = model.table();
  impl_->table = std::make_shared<fcl::Boxd>(t.size.x(), t.size.y(), t.size.z());
  impl_->adjacent.insert(model.baseAdjacentLinks().begin(), model.baseAdjacentLinks().end());
}

CollisionChecker::~CollisionChecker() = default;
CollisionChecker::CollisionChecker(CollisionChecker&&) noexcept = default;

void CollisionChecker::setHeldObject(const TriangleMesh& mesh_O, const Iso3& T_tip_O) {
  impl_->held = bvhOf(mesh_O);
  impl_->T_tip_held = T_tip_O;
}

void CollisionChecker::clearHeldObject() { impl_->held.reset(); }

bool CollisionChecker::inCollision(const JointVector& q, std::string* what) const {
  const RobotModel& m = *impl_->model;
  std::vector<Iso3> T = m.linkPoses(q);
  Iso3 T_table = Iso3(Eigen::Translation3d(m.table().center_B));
  auto say = [&](const std::string& s) {
    if (what) *what = s;
    return true;
  };
  for (const Part& p : impl_->moving) {
    Iso3 Tp = T[p.link] * p.T_link_geom;
    if (collide(p.geom, Tp, impl_->table, T_table))
      return say("link " + m.links()[p.link].name + " hits the table");
    if (impl_->adjacent.count(p.link)) continue;
    for (const Part& f : impl_->fixed)
      if (collide(p.geom, Tp, f.geom, T[f.link] * f.T_link_geom))
        return say("link " + m.links()[p.link].name + " hits the robot's base (" +
                   m.links()[f.link].name + ")");
  }
  if (impl_->held) {
    Iso3 To = T[m.tipLink()] * impl_->T_tip_held;
    if (collide(impl_->held, To, impl_->table, T_table))
      return say("the held object hits the table");
    for (const Part& f : impl_->fixed)
      if (collide(impl_->held, To, f.geom, T[f.link] * f.T_link_geom))
        return say("the held object hits the robot's base (" + m.links()[f.link].name + ")");
  }
  return false;
}

bool CollisionChecker::pathFree(const JointVector& a, const JointVector& b, double step,
                                std::string* what) const {
  INHAND_CHECK(step > 0, "path step must be positive");
  int n = std::max(1, int(std::ceil((b - a).cwiseAbs().maxCoeff() / step)));
  for (int i = 0; i <= n; ++i)
    if (inCollision(a + (b - a) * (double(i) / n), what)) return false;
  return true;
}

// ---- hand ---------------------------------------------------------------------------------------

HandGeometry::HandGeometry(const RobotModel& model, const JointVector& q, const Iso3& T_F_palm)
    : model_(&model) {
  std::vector<Iso3> T = model.linkPoses(q);
  Iso3 T_F_B = T_F_palm * T[model.tipLink()].inverse();
  for (int li : model.handLinks()) {
    T_F_link_.push_back(T_F_B * T[li]);
    T_link_F_.push_back(T_F_link_.back().inverse());
    std::vector<Iso3> geoms;
    std::vector<Aabb> boxes;
    for (const Primitive& p : model.links()[li].collision) {
      geoms.push_back(p.T_link_geom.inverse());
      // The primitive's box in its geometry frame, then its eight corners in F.
      Aabb local;
      if (p.type == Primitive::Type::kMesh) {
        local = p.mesh->bounds();
      } else {
        const Vec3 half = p.type == Primitive::Type::kBox ? Vec3(0.5 * p.size)
                          : p.type == Primitive::Type::kCylinder
                              ? Vec3(p.size.x(), p.size.x(), 0.5 * p.size.z())
                              : Vec3::Constant(p.size.x());
        local.extend(-half);
        local.extend(half);
      }
      const Iso3 T_F_geom = T_F_link_.back() * p.T_link_geom;
      Aabb box;
      for (int c = 0; c < 8; ++c)
        box.extend(T_F_geom * Vec3((c & 1) ? local.max.x() : local.min.x(),
                                   (c & 2) ? local.max.y() : local.min.y(),
                                   (c & 4) ? local.max.z() : local.min.z()));
      boxes.push_back(box);
    }
    T_geom_link_.push_back(std::move(geoms));
    boxes_F_.push_back(std::move(boxes));
  }
}

Aabb HandGeometry::bounds() const {
  Aabb out;
  for (const std::vector<Aabb>& boxes : boxes_F_)
    for (const Aabb& b : boxes) {
      out.extend(b.min);
      out.extend(b.max);
    }
  return out;
}

TriangleMesh HandGeometry::mesh() const {
  TriangleMesh out;
  for (size_t k = 0; k < T_F_link_.size(); ++k)
    for (const Primitive& p : model_->links()[model_->handLinks()[k]].collision)
      out.append(transformed(p.toMesh(), T_F_link_[k]));
  return out;
}

bool HandGeometry::contains(const Vec3& p_F) const {
  for (size_t k = 0; k < T_F_link_.size(); ++k) {
    const Vec3 p_link = T_link_F_[k] * p_F;
    for (const Primitive& p : model_->links()[model_->handLinks()[k]].collision)
      if (p.contains(p_link)) return true;
  }
  return false;
}

double HandGeometry::primitiveDistance(const Primitive& p, const Vec3& q,
                                       const Vec3& p_link) const {
  switch (p.type) {
    case Primitive::Type::kBox: {
      Vec3 e = q.cwiseAbs() - 0.5 * p.size;
      return e.cwiseMax(0.0).norm() + std::min(e.maxCoeff(), 0.0);
    }
    case Primitive::Type::kCylinder: {
      Vec2 e(std::hypot(q.x(), q.y()) - p.size.x(), std::abs(q.z()) - 0.5 * p.size.z());
      return e.cwiseMax(0.0).norm() + std::min(e.maxCoeff(), 0.0);
    }
    case Primitive::Type::kSphere:
      return q.norm() - p.size.x();
    case Primitive::Type::kMesh:
    default:
      return p.contains(p_link) ? 0.0 : std::numeric_limits<double>::infinity();
  }
}

double HandGeometry::distance(const Vec3& p_F, int* nearest) const {
  double best = std::numeric_limits<double>::infinity();
  if (nearest) *nearest = -1;
  for (size_t k = 0; k < T_F_link_.size(); ++k) {
    const Vec3 p_link = T_link_F_[k] * p_F;
    const std::vector<Primitive>& prims = model_->links()[model_->handLinks()[k]].collision;
    for (size_t j = 0; j < prims.size(); ++j) {
      const double d = primitiveDistance(prims[j], T_geom_link_[k][j] * p_link, p_link);
      if (d < best) {
        best = d;
        if (nearest) *nearest = model_->handLinks()[k];
      }
    }
  }
  return best;
}

double HandGeometry::distanceWithin(const Vec3& p_F, double limit, int* nearest) const {
  double best = std::numeric_limits<double>::infinity();
  if (nearest) *nearest = -1;
  for (size_t k = 0; k < T_F_link_.size(); ++k) {
    const std::vector<Primitive>& prims = model_->links()[model_->handLinks()[k]].collision;
    bool linkNear = false;
    Vec3 p_link;
    for (size_t j = 0; j < prims.size(); ++j) {
      const Aabb& b = boxes_F_[k][j];
      if (((p_F - b.min).array() < -limit).any() || ((p_F - b.max).array() > limit).any())
        continue;  // farther than `limit` from the primitive
      if (!linkNear) {
        p_link = T_link_F_[k] * p_F;
        linkNear = true;
      }
      const double d = primitiveDistance(prims[j], T_geom_link_[k][j] * p_link, p_link);
      if (d < best) {
        best = d;
        if (nearest) *nearest = model_->handLinks()[k];
      }
    }
  }
  if (best > limit) {
    if (nearest) *nearest = -1;
    return std::numeric_limits<double>::infinity();
  }
  return best;
}

struct FingerCloser::Geometry {
  GeomPtr object;
  std::map<std::pair<int, int>, GeomPtr>
      linkMesh;  // every hand link's, palm included, by (link, k)
  // Box links against the object's triangles by the separating-axis test (exact for a solid
  // box); without it (reference), every link as a mesh in FCL.
  std::optional<TriangleBoxIndex> boxes;
  // Whether a link's collision geometry k at T_O_link (the link's pose) meets the object.
  bool touches(const RobotModel& model, int li, int k, const Iso3& T_O_link) const {
    const Primitive& p = model.links()[li].collision[k];
    if (boxes && p.type == Primitive::Type::kBox)
      return boxes->overlapsBox(T_O_link * p.T_link_geom, 0.5 * p.size);
    return collide(linkMesh.at({li, k}), T_O_link * p.T_link_geom, object, Iso3::Identity());
  }
};

FingerCloser::FingerCloser(const RobotModel& model, const TriangleMesh& object_O, bool reference)
    : model_(&model) {
  auto g = std::make_shared<Geometry>();
  g->object = bvhOf(object_O);
  if (!reference) g->boxes.emplace(object_O);
  // Other links as triangle meshes: mesh–mesh checks are exact triangle–triangle tests, while
  // FCL's primitive–mesh path (GJK) can miss penetrations of a fraction of a millimetre, which
  // would let the bisection stop slightly inside the object.
  for (int li : model.handLinks())
    for (int k = 0; k < int(model.links()[li].collision.size()); ++k) {
      const Primitive& p = model.links()[li].collision[k];
      g->linkMesh[{li, k}] = bvhOf(transformed(p.toMesh(), p.T_link_geom.inverse()));
    }
  geometry_ = std::move(g);
}

bool FingerCloser::handTouches(const JointVector& q, const Iso3& T_O_palm) const {
  const RobotModel& model = *model_;
  const std::vector<Iso3> T = model.linkPoses(q);
  const Iso3 T_O_B = T_O_palm * T[model.tipLink()].inverse();
  for (int li : model.handLinks())
    for (int k = 0; k < int(model.links()[li].collision.size()); ++k)
      if (geometry_->touches(model, li, k, T_O_B * T[li])) return true;
  return false;
}

std::optional<double> FingerCloser::freeTravel(const JointVector& q, const Iso3& T_O_palm,
                                               const Vec3& dir, double max_travel, double step,
                                               double tolerance) const {
  INHAND_CHECK(step > 0 && tolerance > 0, "approach step and tolerance must be positive");
  auto touches = [&](double s) {
    Iso3 T = T_O_palm;
    T.translation() += s * dir;
    return handTouches(q, T);
  };
  if (touches(0)) return std::nullopt;
  double free = 0;
  for (double s = step; free < max_travel; s += step) {
    const double v = std::min(s, max_travel);
    if (touches(v)) {
      double hit = v;
      while (hit - free > tolerance) {
        const double mid = 0.5 * (hit + free);
        (touches(mid) ? hit : free) = mid;
      }
      return free;
    }
    free = v;
  }
  return max_travel;
}

ClosingResult closeFingers(const RobotModel& model, const JointVector& qIn, const Iso3& T_O_palm,
                           const TriangleMesh& object_O, double step, double tolerance) {
  return FingerCloser(model, object_O).close(qIn, T_O_palm, step, tolerance);
}

ClosingResult FingerCloser::close(const JointVector& qIn, const Iso3& T_O_palm, double step,
                                  double tolerance, const ClosingResult* free_from) const {
  INHAND_CHECK(step > 0 && tolerance > 0, "closing step and tolerance must be positive");
  const RobotModel& model = *model_;
  const Geometry& geometry = *geometry_;
  ClosingResult result;
  result.q = qIn;
  INHAND_CHECK(!free_from || free_from->fingers.size() == model.fingers().size(),
               "free_from: one closing per finger");
  const std::vector<bool> closing = model.closingFingers(qIn);
  for (size_t fi = 0; fi < model.fingers().size(); ++fi) {
    const FingerInfo& f = model.fingers()[fi];
    if (!closing[fi]) {  // stays open (RobotModel::closingFingers)
      FingerClosing fc;
      fc.value = qIn[f.variable];
      fc.free_steps = 0;
      result.fingers.push_back(fc);
      continue;
    }
    // Steps already known free (a finger's links depend only on its own joints and the spread).
    const int known = free_from ? free_from->fingers[fi].free_steps : -1;
    // Collision of this finger's links at finger value v (other joints as in result.q).
    auto touches = [&](double v) {
      JointVector q = result.q;
      q[f.variable] = v;
      model.applyCouplings(&q);
      std::vector<Iso3> T = model.linkPoses(q);
      Iso3 T_O_B = T_O_palm * T[model.tipLink()].inverse();
      for (int li : f.links)
        for (int k = 0; k < int(model.links()[li].collision.size()); ++k)
          if (geometry.touches(model, li, k, T_O_B * T[li])) return true;
      return false;
    };
    FingerClosing fc;
    // From where q has the finger (a preshape between open and closed), towards closed.
    const double start =
        std::clamp(qIn[f.variable], std::min(f.open, f.closed), std::max(f.open, f.closed));
    const double dir = f.closed >= f.open ? 1.0 : -1.0, span = std::abs(f.closed - start);
    double free = start;
    fc.value = f.closed;
    if (known < 0 && touches(start)) {
      fc.value = start;
      fc.contact = true;
    } else {
      int i = 0;
      fc.free_steps = 0;
      for (double s = step; s < span + step; s += step, ++i) {
        double v = start + dir * std::min(s, span);
        if (i < known) {  // free of the superset, so of this object
          free = v;
          fc.free_steps = i + 1;
          continue;
        }
        if (touches(v)) {
          double hit = v;
          while (std::abs(hit - free) > tolerance) {
            double mid = 0.5 * (hit + free);
            (touches(mid) ? hit : free) = mid;
          }
          fc.value = free;  // the last value without penetration
          fc.contact = true;
          break;
        }
        free = v;
        fc.free_steps = i + 1;
      }
    }
    result.q[f.variable] = fc.value;
    model.applyCouplings(&result.q);
    result.fingers.push_back(fc);
  }
  return result;
}

std::pair<ClosingResult, Iso3> closeOffTheTable(const FingerCloser& both,
                                                const FingerCloser& object, const JointVector& q,
                                                const Iso3& T_O_palm, double step,
                                                double max_backoff, double closing_step) {
  Iso3 T = T_O_palm;
  const Vec3 back = -T_O_palm.linear().col(2);
  for (double off = 0;; off += step) {
    T.translation() = T_O_palm.translation() + off * back;
    ClosingResult r = both.close(q, T, closing_step, 1e-4);
    if (off + step > max_backoff + 1e-9) return {r, T};
    bool blocked = false;
    const ClosingResult alone = object.close(q, T, closing_step, 1e-4, &r);
    for (size_t k = 0; k < r.fingers.size(); ++k) {
      const FingerInfo& f = both.model().fingers()[k];
      const double dir = f.closed >= f.open ? 1.0 : -1.0;
      if (r.fingers[k].contact && dir * (alone.fingers[k].value - r.fingers[k].value) > 1e-3)
        blocked = true;
    }
    if (!blocked) return {r, T};
    // Backed off, the hand must not leave the object altogether: stop when nothing touches.
    bool any = false;
    for (const FingerClosing& f : alone.fingers) any = any || f.contact;
    if (!any) return {r, T};
  }
}

namespace {
double handTip(const RobotModel& model, const JointVector& open) {
  double tip = -std::numeric_limits<double>::infinity();
  for (const Vec3f& v : HandGeometry(model, open, Iso3::Identity()).mesh().vertices)
    tip = std::max(tip, double(v.z()));
  return tip;
}
}  // namespace

double openHandReach(const RobotModel& model) {
  return handTip(model, model.withFingersOpen(model.home())) - model.palmFaceZ();
}

double openHandDepth(const RobotModel& model, int axis, double width, double spread,
                     double edge_x) {
  if (axis != 0 && axis != 1) throw Error("openHandDepth: axis must be 0 (palm x) or 1 (palm y)");
  if (!(width > 0)) throw Error("openHandDepth: width must be positive");
  const JointVector open = model.openHand(spread);
  const double tip = handTip(model, open);
  // The slab's face 5 cm beyond the fingertips; the hand moves towards it along palm z.
  Vec3 size(1.0, 1.0, 0.02), centre(0, 0, 0);
  size[axis] = width;
  if (std::isfinite(edge_x)) {
    size.x() = 0.5;
    centre.x() = edge_x - 0.25;
  }
  const double face = tip + 0.05;
  centre.z() = face + 0.01;
  const TriangleMesh slab = transformed(makeBox(size), Iso3(Eigen::Translation3d(centre)));
  const double reach = tip - model.palmFaceZ();
  const std::optional<double> travel =
      FingerCloser(model, slab)
          .freeTravel(open, Iso3::Identity(), Vec3::UnitZ(), 0.05 + reach + 0.05, 0.005, 2e-4);
  if (!travel) return 0;
  // Where the slab's face sits in the hand's frame at the stop, below the fingertips.
  return std::clamp(*travel - 0.05, 0.0, reach);
}

TriangleMesh tableMeshInObject(const RobotModel& robot, const Iso3& T_B_O) {
  const TableInfo& t = robot.table();
  return transformed(makeBox(t.size), T_B_O.inverse() * Eigen::Translation3d(t.center_B));
}

}  // namespace inhand
