// Python bindings of inhand (module inhand._inhand; the package inhand re-exports it). Poses are
// 4×4 numpy arrays (float64), joint states 1-D float64 arrays, depth images H×W float32 arrays in
// metres (0: no return). Arrays of models and frames are views of the C++ data (no copies); the
// heavy calls (integration, extraction, planning, scans) release the GIL.
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <memory>
#include <optional>

#include "inhand/inhand.h"

namespace py = pybind11;
using namespace inhand;

namespace {

std::string& dataDir() {
  static std::string dir = INHAND_DATA_DIR;
  return dir;
}

Iso3 isoFrom(const Eigen::Matrix4d& m, const char* what) {
  std::array<double, 16> a{};
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) a[size_t(r * 4 + c)] = m(r, c);
  std::string why;
  const std::optional<Iso3> T = poseFromRowMajor(a, &why);  // nearest rotation within 1e-2
  if (!T) throw Error(std::string(what) + ": not a rigid transform: " + why);
  return *T;
}
Eigen::Matrix4d matrixOf(const Iso3& T) { return T.matrix(); }

// A depth image from an H×W float32 array (metres), checked against the camera.
DepthImage depthFrom(const py::array_t<float, py::array::c_style | py::array::forcecast>& a,
                     const CameraIntrinsics* K) {
  if (a.ndim() != 2) throw Error("depth_m: expected an H×W array of metres");
  DepthImage d(int(a.shape(1)), int(a.shape(0)));
  std::copy(a.data(), a.data() + a.size(), d.depth_m.begin());
  if (K && (d.width != K->width || d.height != K->height))
    throw Error("depth_m: " + std::to_string(d.width) + "x" + std::to_string(d.height) +
                " pixels, the camera's are " + std::to_string(K->width) + "x" +
                std::to_string(K->height));
  return d;
}

// An H×W float32 array owning the image's pixels (moved, not copied).
py::array_t<float> depthArray(DepthImage&& d) {
  auto* owner = new std::vector<float>(std::move(d.depth_m));
  py::capsule free(owner, [](void* p) { delete static_cast<std::vector<float>*>(p); });
  return py::array_t<float>(std::vector<py::ssize_t>{d.height, d.width}, owner->data(), free);
}

// A JSON value as Python objects (null: None).
py::object pyFrom(const Json& j) {
  switch (j.type()) {
    case Json::value_t::object: {
      py::dict d;
      for (const auto& [k, v] : j.items()) d[py::str(k)] = pyFrom(v);
      return d;
    }
    case Json::value_t::array: {
      py::list l;
      for (const Json& v : j) l.append(pyFrom(v));
      return l;
    }
    case Json::value_t::string:
      return py::str(j.get<std::string>());
    case Json::value_t::boolean:
      return py::bool_(j.get<bool>());
    case Json::value_t::number_integer:
    case Json::value_t::number_unsigned:
      return py::int_(j.get<long long>());
    case Json::value_t::number_float:
      return py::float_(j.get<double>());
    default:
      return py::none();
  }
}

// A view's record as summary.json writes it (scan/records.h), its vectors as numpy arrays, its
// unknown figures NaN.
py::dict viewDict(const ViewRecord& r, int grasp) {
  py::dict d = pyFrom(viewRecordJson(r));
  d["grasp"] = grasp;
  d["direction_O"] = Eigen::Vector3d(r.dir_O);
  d["T_O_C"] = matrixOf(r.T_O_C);
  d["predicted_gain"] = r.gain;  // NaN for the initial views
  d["t_q"] = r.t_q;
  return d;
}

ScanConfig configFrom(const py::object& options) {
  ScanConfig c;
  if (!options.is_none()) {
    const std::string text = py::module_::import("json").attr("dumps")(options).cast<std::string>();
    readScanConfig(Json::parse(text), "options", &c);
  }
  return c;
}

// The simulator for Python: a SimWorld with its robot and sensor.
struct Simulator {
  Simulator(std::shared_ptr<RobotModel> model, const std::string& object, const py::object& options,
            uint64_t seed, const std::string& start)
      : model(std::move(model)), mesh(loadObject(object)) {
    ScanConfig c = configFrom(options);
    c.sim.seed = seed;
    if (std::string p = c.sim.validate(); !p.empty()) throw Error("simulation options: " + p);
    const auto [T, q] = defaultGrasp(*this->model, mesh);
    grasp_T_O_palm = T;
    grasp_q = q;
    world = std::make_unique<SimWorld>(*this->model, mesh, T, camera, NoiseModelOptions{}, c.sim);
    if (start == "held") {
      world->holdAt(q);
      grasp_T_O_palm = world->T_O_palm;  // where the squeeze left it (physics)
      grasp_q = world->q;
    } else if (start == "table") {
      world->held = false;
      world->q = this->model->home();
    } else {
      throw Error("start: must be table or held");
    }
    robot = std::make_unique<SimRobot>(world.get());
    sensor = std::make_unique<SimSensor>(world.get(), camera);
  }
  std::shared_ptr<RobotModel> model;
  TriangleMesh mesh;
  DepthCameraOptions camera;
  Iso3 grasp_T_O_palm = Iso3::Identity();
  JointVector grasp_q;
  std::unique_ptr<SimWorld> world;
  std::unique_ptr<SimRobot> robot;
  std::unique_ptr<SimSensor> sensor;
};

// Recorded frames (frames.json + depth PNGs).
struct Frames {
  std::filesystem::path dir;
  FrameSet set;
};

// A ScanSession with the robot model it refers to kept alive.
struct Session {
  std::shared_ptr<RobotModel> model;
  std::unique_ptr<ScanSession> s;
};

// The bindings of the camera intrinsics and the model (arrays are views of its data).
void bindCameraAndModel(py::module_& m) {
  py::class_<CameraIntrinsics>(m, "Camera", "pinhole intrinsics (pixels)")
      .def(py::init<>())
      .def(py::init([](int width, int height, double fx, double fy, double cx, double cy) {
             CameraIntrinsics K;
             K.width = width;
             K.height = height;
             K.fx = fx;
             K.fy = fy;
             K.cx = cx;
             K.cy = cy;
             if (std::string p = K.validate(); !p.empty()) throw Error("camera: " + p);
             return K;
           }),
           py::arg("width"), py::arg("height"), py::arg("fx"), py::arg("fy"), py::arg("cx"),
           py::arg("cy"))
      .def_readwrite("width", &CameraIntrinsics::width)
      .def_readwrite("height", &CameraIntrinsics::height)
      .def_readwrite("fx", &CameraIntrinsics::fx)
      .def_readwrite("fy", &CameraIntrinsics::fy)
      .def_readwrite("cx", &CameraIntrinsics::cx)
      .def_readwrite("cy", &CameraIntrinsics::cy)
      .def("__repr__", [](const CameraIntrinsics& K) {
        return "Camera(" + std::to_string(K.width) + "x" + std::to_string(K.height) +
               ", fx=" + std::to_string(K.fx) + ")";
      });

  // The model: arrays are views of its data, valid while the model lives.
  py::class_<ObjectModel, std::shared_ptr<ObjectModel>>(m, "Model",
                                                        "a model S_obj: mesh with variance")
      .def_property_readonly(
          "vertices",
          [](py::object self) {
            auto& o = self.cast<ObjectModel&>();
            return py::array_t<float>({py::ssize_t(o.mesh.vertices.size()), py::ssize_t(3)},
                                      reinterpret_cast<const float*>(o.mesh.vertices.data()), self);
          },
          "N×3 float32, metres, object frame O")
      .def_property_readonly(
          "faces",
          [](py::object self) {
            auto& o = self.cast<ObjectModel&>();
            return py::array_t<int>({py::ssize_t(o.mesh.triangles.size()), py::ssize_t(3)},
                                    reinterpret_cast<const int*>(o.mesh.triangles.data()), self);
          },
          "M×3 int32 vertex indices, outward")
      .def_property_readonly(
          "variance",
          [](py::object self) {
            auto& o = self.cast<ObjectModel&>();
            return py::array_t<float>({py::ssize_t(o.variance.size())}, o.variance.data(), self);
          },
          "N float32 surface variance, m² (σ = 5 cm: never observed)")
      .def_property_readonly(
          "observed",
          [](py::object self) {
            auto& o = self.cast<ObjectModel&>();
            return py::array_t<uint8_t>({py::ssize_t(o.observed.size())}, o.observed.data(), self);
          },
          "N uint8: 1 measured, 0 hole-filled")
      .def_property_readonly(
          "rgba",
          [](py::object self) {
            auto& o = self.cast<ObjectModel&>();
            return py::array_t<uint8_t>({py::ssize_t(o.rgba.size()), py::ssize_t(4)},
                                        reinterpret_cast<const uint8_t*>(o.rgba.data()), self);
          },
          "N×4 uint8 scanned colour (sRGB) and alpha (255: colour seen, 0: none); N×4 empty "
          "(0 rows) without a colour camera")
      .def("mean_entropy", &ObjectModel::meanEntropy, "paper Fig. 5: mean ½ ln(2πe σ²), nats")
      .def("observed_fraction", &ObjectModel::observedAreaFraction)
      .def("hole_area_m2", &ObjectModel::holeArea)
      .def("observed_surface",
           [](const ObjectModel& o) { return std::make_shared<ObjectModel>(o.observedSurface()); })
      .def(
          "save_ply",
          [](const ObjectModel& o, const std::filesystem::path& path) {
            writePly(path, o.mesh, &o.variance, o.rgba.empty() ? nullptr : &o.rgba);
          },
          py::arg("path"),
          "binary PLY with per-vertex variance and the scanned colours (confidence colours "
          "without a colour camera)")
      .def("__repr__", [](const ObjectModel& o) {
        return "Model(" + std::to_string(o.mesh.vertices.size()) + " vertices, " +
               std::to_string(o.mesh.triangles.size()) + " faces)";
      });
}

// The bindings of recorded frames and the volume.
void bindFramesAndVolume(py::module_& m) {
  py::class_<Frames>(m, "Frames", "a directory of depth frames with camera poses")
      .def("__len__", [](const Frames& f) { return f.set.frames.size(); })
      .def(
          "__getitem__",
          [](const Frames& f, py::ssize_t i) {
            const py::ssize_t n = py::ssize_t(f.set.frames.size());
            if (i < 0) i += n;
            if (i < 0 || i >= n) throw py::index_error("frame index out of range");
            DepthImage d = loadFrameDepth(f.dir, f.set, size_t(i));
            py::object frame = py::module_::import("types").attr("SimpleNamespace")();
            frame.attr("depth_m") = depthArray(std::move(d));
            const FrameRecord& r = f.set.frames[size_t(i)];
            frame.attr("T_O_C") = r.has_T_O_C ? py::cast(matrixOf(r.T_O_C)) : py::none();
            frame.attr("file") = r.file;
            // A robot's frame: the joints by name, the camera in the base frame, the palm in
            // the object frame (None where the file gives none).
            py::dict q;
            for (const auto& [name, value] : r.q) q[py::str(name)] = value;
            frame.attr("q") = q.empty() ? py::object(py::none()) : py::object(q);
            frame.attr("T_B_C") = r.T_B_C ? py::cast(matrixOf(*r.T_B_C)) : py::none();
            const std::optional<Iso3> palm = r.T_O_palm ? r.T_O_palm : f.set.T_O_palm;
            frame.attr("T_O_palm") = palm ? py::cast(matrixOf(*palm)) : py::none();
            return frame;
          },
          "frame i: .depth_m (H×W float32, m), .T_O_C (4×4, or None), .file; from a robot also "
          ".q (dict of joint values), .T_B_C and .T_O_palm (4×4)")
      .def_property_readonly("camera", [](const Frames& f) { return f.set.intrinsics; })
      .def_property_readonly("bounds_min",
                             [](const Frames& f) -> std::optional<Eigen::Vector3d> {
                               if (!f.set.bounds_O) return std::nullopt;
                               return f.set.bounds_O->min;
                             })
      .def_property_readonly("bounds_max", [](const Frames& f) -> std::optional<Eigen::Vector3d> {
        if (!f.set.bounds_O) return std::nullopt;
        return f.set.bounds_O->max;
      });
  m.def(
      "load_frames",
      [](const std::filesystem::path& dir) {
        return Frames{dir, readFrameSet(dir)};
      },
      py::arg("dir"), "reads DIR/frames.json (every field checked; errors name file and field)");

  py::class_<TsdfVolume>(m, "Volume", "the TSDF volume with per-voxel variance (§III)")
      .def(py::init([](const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double voxel_m,
                       double truncation_m, double memory_mb, double band_sigmas,
                       bool smooth_depth) {
             if (!((hi - lo).array() > 0).all())
               throw Error("Volume: bounds_max must exceed bounds_min on every axis");
             Aabb box;
             box.extend(lo);
             box.extend(hi);
             VolumeOptions o;
             o.voxel_size_m = voxel_m;
             o.truncation_m = truncation_m;
             o.memory_budget_mb = memory_mb;
             o.band_sigmas = band_sigmas;
             o.smooth_depth = smooth_depth;
             if (std::string p = o.validate(); !p.empty()) throw Error("Volume: " + p);
             return TsdfVolume(box, o);
           }),
           py::arg("bounds_min"), py::arg("bounds_max"), py::arg("voxel_m") = 0.002,
           py::arg("truncation_m") = 0.0, py::arg("memory_mb") = 2048.0,
           py::arg("band_sigmas") = 2.0, py::arg("smooth_depth") = true)
      .def_property_readonly("dims", [](const TsdfVolume& v) { return Eigen::Vector3i(v.dims()); })
      .def_property_readonly("voxel_m", &TsdfVolume::voxelSize)
      .def_property_readonly("origin",
                             [](const TsdfVolume& v) { return Eigen::Vector3d(v.origin()); })
      .def(
          "integrate",
          [](TsdfVolume& v,
             const py::array_t<float, py::array::c_style | py::array::forcecast>& depth,
             const Eigen::Matrix4d& T_O_C, const CameraIntrinsics& K) {
            const DepthImage d = depthFrom(depth, &K);
            const Iso3 T = isoFrom(T_O_C, "T_O_C");
            py::gil_scoped_release release;
            const NoiseModelOptions noise;
            integrate(d, T, K, measurementSigma(d, K, noise), &v);
          },
          py::arg("depth_m"), py::arg("T_O_C"), py::arg("camera"),
          "fuses a depth image (H×W metres) taken from camera pose T_O_C (object frame)")
      .def(
          "extract",
          [](const TsdfVolume& v, const std::string& surface, double hole_sigma_m) {
            if (surface != "closed" && surface != "observed")
              throw Error("surface: must be closed or observed");
            MeshOptions o;
            o.hole_sigma_m = hole_sigma_m;
            py::gil_scoped_release release;
            ObjectModel model = extractModel(v, o);
            return std::make_shared<ObjectModel>(surface == "closed" ? std::move(model)
                                                                     : model.observedSurface());
          },
          py::arg("surface") = "closed", py::arg("hole_sigma_m") = 0.05,
          "the model: closed (hole-filled over the unseen, the paper's) or the observed surface");
}

// The bindings of the robot model.
void bindRobot(py::module_& m) {
  py::class_<RobotModel, std::shared_ptr<RobotModel>>(m, "Robot", "robot model (URDF + config)")
      .def_static(
          "load",
          [](const std::string& config) {
            const std::filesystem::path p =
                config.empty() ? std::filesystem::path(dataDir()) / "robots/wam_barretthand.json"
                               : std::filesystem::path(config);
            return std::make_shared<RobotModel>(RobotModel::load(p));
          },
          py::arg("config") = "",
          "loads a robot config JSON (default: the Barrett WAM with BarrettHand)")
      .def_property_readonly("name", &RobotModel::name)
      .def_property_readonly("variable_count", &RobotModel::variableCount)
      .def_property_readonly("variable_names",
                             [](const RobotModel& r) {
                               std::vector<std::string> names;
                               for (int v = 0; v < r.variableCount(); ++v)
                                 names.push_back(r.variable(v).name);
                               return names;
                             })
      .def_property_readonly("grasp_offset", &RobotModel::graspOffset,
                             "palm-to-object-centre distance of a held object, m")
      .def("home", &RobotModel::home)
      .def(
          "with_arm_of",
          [](const RobotModel& r, const Eigen::VectorXd& q, const Eigen::VectorXd& other) {
            if (q.size() != r.variableCount() || other.size() != r.variableCount())
              throw Error("q: wrong number of joint values");
            return r.withArm(q, r.arm(other));
          },
          py::arg("q"), py::arg("other"), "q with the arm joints of `other` (the hand as in q)")
      .def(
          "tip_pose",
          [](const RobotModel& r, const Eigen::VectorXd& q) {
            if (q.size() != r.variableCount()) throw Error("q: wrong number of joint values");
            return matrixOf(r.tipPose(q));
          },
          py::arg("q"), "T_B_palm at joint state q");
}

// The bindings of ScanSession and what it returns.
void bindSession(py::module_& m) {
  py::class_<PlannedView>(m, "PlannedView", "a view ScanSession chose")
      .def_readonly("initial", &PlannedView::initial)
      .def_property_readonly("dir_O", [](const PlannedView& v) { return Eigen::Vector3d(v.dir_O); })
      .def_property_readonly("T_O_C", [](const PlannedView& v) { return matrixOf(v.T_O_C); })
      .def_readonly("waypoints", &PlannedView::waypoints)
      .def_readonly("quality", &PlannedView::quality)
      .def_readonly("cost_s", &PlannedView::cost_s)
      .def_readonly("score", &PlannedView::score)
      .def_readonly("candidates", &PlannedView::candidates);

  py::class_<GraspCandidate>(m, "GraspCandidate")
      .def_property_readonly("T_O_palm",
                             [](const GraspCandidate& g) { return matrixOf(g.T_O_palm); })
      .def_readonly("q", &GraspCandidate::q)
      .def_readonly("q_open", &GraspCandidate::q_open)
      .def_readonly("q_lift", &GraspCandidate::q_lift)
      .def_readonly("quality", &GraspCandidate::quality)
      .def_readonly("epsilon", &GraspCandidate::epsilon);

  py::class_<ScanSession::Summary>(m, "Summary")
      .def_property_readonly(
          "termination",
          [](const ScanSession::Summary& s) { return terminationName(s.termination); })
      .def_readonly("message", &ScanSession::Summary::message)
      .def_readonly("grasps", &ScanSession::Summary::grasps)
      .def_readonly("views", &ScanSession::Summary::views)
      .def_readonly("frames", &ScanSession::Summary::frames)
      .def_readonly("view_evaluations", &ScanSession::Summary::view_evaluations)
      .def_readonly("planning_s", &ScanSession::Summary::planning_s)
      .def_readonly("fusion_s", &ScanSession::Summary::fusion_s)
      .def_readonly("frames_rejected", &ScanSession::Summary::frames_rejected)
      .def_readonly("frames_moving", &ScanSession::Summary::frames_moving)
      .def_property_readonly(
          "slips", [](const ScanSession::Summary& s) { return slipsJson(s.slips).dump(); },
          "the slips found in the hand, as summary.json's slips_found (a JSON string)")
      .def_readonly("tracking_s", &ScanSession::Summary::tracking_s)
      .def_property_readonly(
          "payload",
          [](const ScanSession::Summary& s) -> py::object {
            if (!s.payload) return py::none();
            py::dict d;
            d["mass_kg"] = s.payload->mass_kg;
            d["sigma_kg"] = s.payload->sigma_kg;
            d["com_O"] = s.payload->com_observed ? py::cast(s.payload->com) : py::none();
            d["readings"] = s.payload->readings;
            return d;
          },
          "the object weighed from add_joint_torques' readings (dict), or None")
      .def("__repr__", &ScanSession::Summary::brief);

  py::class_<Session>(m, "ScanSession", "the scan driven from the caller's own loop")
      .def(py::init([](std::shared_ptr<RobotModel> robot, const Eigen::Vector3d& centre,
                       const py::object& options, std::optional<CameraIntrinsics> camera) {
             const ScanConfig c = configFrom(options);
             DepthCameraOptions cam;
             if (camera) cam.intrinsics = *camera;
             Session s{robot, nullptr};
             s.s = std::make_unique<ScanSession>(*robot, cam, NoiseModelOptions{}, c.scan, c.multi,
                                                 centre);
             return s;
           }),
           py::arg("robot"), py::arg("centre"), py::arg("options") = py::none(),
           py::arg("camera") = py::none(),
           "a model around centre (object frame); options: a dict as in docs/config.md")
      .def_static(
          "load",
          [](const std::filesystem::path& path, std::shared_ptr<RobotModel> robot,
             const py::object& options, std::optional<CameraIntrinsics> camera) {
            const ScanConfig c = configFrom(options);
            DepthCameraOptions cam;
            if (camera) cam.intrinsics = *camera;
            return Session{robot, std::make_unique<ScanSession>(ScanSession::load(
                                      path, *robot, cam, NoiseModelOptions{}, c.scan, c.multi))};
          },
          py::arg("path"), py::arg("robot"), py::arg("options") = py::none(),
          py::arg("camera") = py::none(), "resumes from a checkpoint written by save()")
      .def(
          "begin_grasp",
          [](Session& s, const Eigen::Matrix4d& T_O_palm, const Eigen::VectorXd& q,
             std::optional<std::pair<Eigen::Vector3d, Eigen::Vector3d>> box) {
            Aabb b;
            if (box) {
              b.extend(box->first);
              b.extend(box->second);
            }
            py::gil_scoped_release release;
            s.s->beginGrasp(isoFrom(T_O_palm, "T_O_palm"), q, b);
          },
          py::arg("T_O_palm"), py::arg("q"), py::arg("object_box") = py::none())
      .def("end_grasp", [](Session& s) { s.s->endGrasp(); })
      .def(
          "add_frame",
          [](Session& s, const py::array_t<float, py::array::c_style | py::array::forcecast>& depth,
             const Eigen::VectorXd& q, const Eigen::Matrix4d& T_B_C) {
            const DepthImage d = depthFrom(depth, nullptr);
            const Iso3 T = isoFrom(T_B_C, "T_B_C");
            py::gil_scoped_release release;
            const FrameReport r = s.s->addFrame(d, q, T);
            py::gil_scoped_acquire acquire;
            py::dict out;
            out["fused"] = r.fused;
            out["refusal"] = frameRefusalName(r.refusal);
            out["rejected"] = r.rejected;
            out["pixels"] = r.pixels;
            out["carve_pixels"] = r.carve_pixels;
            out["T_B_C"] = matrixOf(r.T_B_C);
            out["tracking_inliers"] = r.tracking_inliers;
            return out;
          },
          py::arg("depth_m"), py::arg("q"), py::arg("T_B_C"),
          "fuses a frame taken from T_B_C with the robot at q (hand-aware, tracked when "
          "options tracking.enabled); returns a dict: fused, rejected (why not), pixels, "
          "carve_pixels, T_B_C (the pose fused with), tracking_inliers")
      .def(
          "next_view",
          [](Session& s, const Eigen::VectorXd& q) {
            py::gil_scoped_release release;
            return s.s->nextView(q);
          },
          py::arg("q"), "the next view (Alg. 1), or None when this grasp's views are done")
      .def("finish_view",
           [](Session& s) {
             const ViewRecord& r = s.s->finishView();
             return viewDict(r, s.s->viewGrasps().back());
           })
      .def(
          "next_grasp",
          [](Session& s, const Eigen::Matrix4d& T_B_O_rest, const Eigen::VectorXd& q) {
            const Iso3 T = isoFrom(T_B_O_rest, "T_B_O_rest");
            py::gil_scoped_release release;
            return s.s->nextGrasp(T, q);
          },
          py::arg("T_B_O_rest"), py::arg("q"),
          "the best grasp candidate on the model so far (ranked by eq. 9), or None")
      .def_property_readonly("views",
                             [](const Session& s) {
                               py::list out;
                               for (size_t i = 0; i < s.s->views().size(); ++i)
                                 out.append(viewDict(s.s->views()[i], s.s->viewGrasps()[i]));
                               return out;
                             })
      .def("camera_pose", [](const Session& s) { return matrixOf(s.s->cameraPose()); })
      .def("model",
           [](const Session& s) {
             py::gil_scoped_release release;
             return std::make_shared<ObjectModel>(s.s->model());
           })
      .def("summary", [](const Session& s) { return s.s->summary(); })
      .def(
          "add_joint_torques",
          [](Session& s, const Eigen::VectorXd& q, const Eigen::VectorXd& tau) {
            s.s->addJointTorques(q, tau);
          },
          py::arg("q"), py::arg("tau"),
          "the arm's joint torques (N·m) read at rest with the object held: they weigh it "
          "(summary().payload)")
      .def(
          "save", [](const Session& s, const std::filesystem::path& p) { s.s->save(p); },
          py::arg("path"), "a checkpoint (written atomically)");
}

// The bindings of the simulator and the simulated scan.
void bindSimulator(py::module_& m) {
  py::class_<Simulator>(m, "Simulator", "the simulated robot, camera, table and object")
      .def(py::init([](std::shared_ptr<RobotModel> robot, const std::string& object,
                       const py::object& options, uint64_t seed, const std::string& start) {
             return std::make_unique<Simulator>(robot, object, options, seed, start);
           }),
           py::arg("robot"), py::arg("object") = "builtin:coffee_can",
           py::arg("options") = py::none(), py::arg("seed") = 1, py::arg("start") = "held")
      .def_property_readonly("q", [](const Simulator& s) { return s.world->q; })
      .def_property_readonly("camera", [](const Simulator& s) { return s.camera.intrinsics; })
      .def_property_readonly("grasp_T_O_palm",
                             [](const Simulator& s) { return matrixOf(s.grasp_T_O_palm); })
      .def_property_readonly("grasp_q", [](const Simulator& s) { return s.grasp_q; })
      .def_property_readonly("rest_pose",
                             [](const Simulator& s) { return matrixOf(s.world->restPose()); })
      .def_property_readonly("held", [](const Simulator& s) { return s.world->held; })
      .def_property_readonly("truth",
                             [](const Simulator& s) {
                               auto o = std::make_shared<ObjectModel>();
                               o->mesh = s.mesh;
                               o->variance.assign(s.mesh.vertices.size(), 0.f);
                               o->observed.assign(s.mesh.vertices.size(), 1);
                               return o;
                             })
      .def("camera_pose", [](const Simulator& s) { return matrixOf(s.sensor->pose()); })
      .def("point_camera",
           [](Simulator& s, const Eigen::Matrix4d& T_B_C) {
             s.sensor->setPose(isoFrom(T_B_C, "T_B_C"));
           })
      .def("capture",
           [](Simulator& s) {
             DepthImage d;
             {
               py::gil_scoped_release release;
               d = s.sensor->capture();
             }
             return depthArray(std::move(d));
           })
      .def(
          "execute",
          [](Simulator& s, const std::vector<Eigen::VectorXd>& waypoints,
             const std::function<void(const Eigen::VectorXd&)>& on_state) {
            s.robot->execute(std::vector<JointVector>(waypoints.begin(), waypoints.end()),
                             [&](const JointVector& q) { on_state(q); });
          },
          py::arg("waypoints"), py::arg("on_state"),
          "moves along joint waypoints, calling on_state(q) at each sensor frame")
      .def("put_down", [](Simulator& s) { return s.robot->putDown(); })
      .def(
          "joint_torques", [](Simulator& s) { return *s.robot->jointTorques(); },
          "the joint torques the simulated arm reports now, at rest (N·m; sim.torque_noise_nm)")
      .def_property_readonly("object_mass_kg",
                             [](const Simulator& s) { return s.world->objectMass_kg(); })
      .def(
          "pick_up",
          [](Simulator& s, const Eigen::Matrix4d& T_O_palm,
             const Eigen::VectorXd& q_open) -> std::optional<Eigen::Matrix4d> {
            std::optional<Iso3> a;
            {
              py::gil_scoped_release release;
              a = s.robot->pickUp(isoFrom(T_O_palm, "T_O_palm"), q_open);
            }
            if (!a) return std::nullopt;
            return matrixOf(*a);
          },
          py::arg("T_O_palm"), py::arg("q_open"),
          "grasps the object where it rests; the achieved T_O_palm or None");

  py::class_<SimulatedScan>(m, "ScanResult", "a simulated scan's outcome")
      .def_property_readonly(
          "model",
          [](const SimulatedScan& s) { return std::make_shared<ObjectModel>(s.result.scan.model); })
      .def_property_readonly(
          "termination",
          [](const SimulatedScan& s) { return terminationName(s.result.scan.termination); })
      .def_property_readonly("grasps",
                             [](const SimulatedScan& s) { return s.result.grasps.size(); })
      .def_property_readonly("frames", [](const SimulatedScan& s) { return s.result.scan.frames; })
      .def_property_readonly("views",
                             [](const SimulatedScan& s) {
                               py::list out;
                               for (const ViewRecord& v : s.result.scan.views)
                                 out.append(viewDict(v, -1));
                               return out;
                             })
      .def_property_readonly("coverage", [](const SimulatedScan& s) { return s.metrics.coverage; })
      .def_property_readonly("accuracy_mean_mm",
                             [](const SimulatedScan& s) { return s.metrics.accuracy_mean_mm; })
      .def_property_readonly("seconds",
                             [](const SimulatedScan& s) { return s.result.scan.total_s; })
      .def("__repr__", [](const SimulatedScan& s) {
        return "ScanResult(" + terminationName(s.result.scan.termination) + ", " +
               std::to_string(s.result.grasps.size()) + " grasps, " +
               std::to_string(s.result.scan.views.size()) + " views, coverage " +
               std::to_string(s.metrics.coverage) + ")";
      });
}

// inhand.scan: the whole simulated scan.
void bindScan(py::module_& m) {
  m.def(
      "scan",
      [](const std::string& object, std::shared_ptr<RobotModel> robot, const py::object& options,
         uint64_t seed, std::optional<int> max_grasps, bool log) {
        ScanConfig c = configFrom(options);
        c.sim.seed = seed;
        c.scan.planner.seed = seed;
        if (max_grasps) c.multi.max_grasps = *max_grasps;
        if (!robot)
          robot = std::make_shared<RobotModel>(
              RobotModel::load(std::filesystem::path(dataDir()) / "robots/wam_barretthand.json"));
        const TexturedMesh mesh = loadSimulatedObject(object, c.sim.colour.enabled);
        ScanProgress progress;
        if (log)
          progress.log = [](const std::string& s) {
            std::fprintf(stderr, "scan: %s\n", s.c_str());
          };
        py::gil_scoped_release release;
        return runSimulatedScan(*robot, mesh.mesh, c, progress, {}, mesh.colours);
      },
      py::arg("object"), py::arg("robot") = nullptr, py::arg("options") = py::none(),
      py::arg("seed") = 1, py::arg("max_grasps") = py::none(), py::arg("log") = false,
      "the whole autonomous scan in the simulator (as inhand scan): object builtin:NAME or a "
      "mesh file");
}

}  // namespace

PYBIND11_MODULE(_inhand, m) {
  m.doc() = "inhand: autonomous in-hand 3D modelling of unknown objects (Krainin et al. 2011)";
  py::register_exception<Error>(m, "Error", PyExc_RuntimeError);
  m.def("_set_data_dir", [](const std::string& d) { dataDir() = d; });
  m.def("_built_in_data_dir", [] { return std::string(INHAND_DATA_DIR); });
  bindCameraAndModel(m);
  bindFramesAndVolume(m);
  bindRobot(m);
  bindSession(m);
  bindSimulator(m);
  bindScan(m);
}
