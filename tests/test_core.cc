#include <gtest/gtest.h>

#include <fstream>
#include <mutex>
#include <set>
#include <stdexcept>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/internal/fast_math.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/json_util.h"
#include "inhand/core/pose.h"
#include "inhand/core/random.h"
#include "test_util.h"

using namespace inhand;

TEST(FastMath, Log1pMatchesLibmOverTheRangeEq9Uses) {
  // x = σ_t²/σ_z² runs from about 1e-6 (well observed) to 1e4 (hole-filled, σ = 5 cm); checked
  // from 0 to 1e12, densely around the series switch at 1e-3 and the mantissa switch at √2.
  double worst = 0;
  int n = 0;
  for (double x = 1e-12; x < 1e12; x *= 1.0007, ++n) {
    const double a = log1pNonNegative(x), b = std::log1p(x);
    worst = std::max(worst, std::abs(a - b) / b);
  }
  for (double x : {0.9e-3, 0.99999e-3, 1e-3, 1.00001e-3, 0.41421356, 0.41421357, 1.0, 3.0})
    worst = std::max(worst, std::abs(log1pNonNegative(x) - std::log1p(x)) / std::log1p(x));
  EXPECT_GT(n, 50000);
  EXPECT_LT(worst, 1e-12);
  EXPECT_EQ(log1pNonNegative(0.0), 0.0);
}

#if INHAND_FAST_MATH_AVX2
__attribute__((target("avx2"))) void log1pFour(const double* x, double* out) {
  _mm256_storeu_pd(out, log1pNonNegativeFour(_mm256_loadu_pd(x)));
}
#endif

TEST(FastMath, Log1pFourAtATimeIsBitForBitOneAtATime) {
#if INHAND_FAST_MATH_AVX2
  if (!fastMathAvx2()) GTEST_SKIP() << "no AVX2 on this CPU";
  std::vector<double> xs = {0.0,        0.9e-3,     0.99999e-3, 1e-3, 1.00001e-3,
                            0.41421356, 0.41421357, 1.0,        3.0,  1e12};
  for (double x = 1e-12; x < 1e12; x *= 1.0013) xs.push_back(x);
  while (xs.size() % 4) xs.push_back(2.0);
  int differ = 0;
  for (size_t k = 0; k < xs.size(); k += 4) {
    double out[4];
    log1pFour(&xs[k], out);
    for (int l = 0; l < 4; ++l) differ += out[l] != log1pNonNegative(xs[k + size_t(l)]);
  }
  EXPECT_EQ(differ, 0);
#else
  GTEST_SKIP() << "no AVX2 build";
#endif
}

// The single-precision functions of the simulated sensor's noise against libm in double.
TEST(FastMath, SinglePrecisionNoiseFunctionsFollowLibm) {
  double logWorst = 0, sinCosWorst = 0, acosWorst = 0;
  for (uint32_t k = 0; k < (1u << 24); k += 97) {  // every uniform's form: k·2^-24 (+ ½)
    const float u1 = (float(int32_t(k)) + 0.5f) * 0x1.0p-24f, u2 = float(int32_t(k)) * 0x1.0p-24f;
    logWorst = std::max(logWorst, std::abs(logPositiveF(u1) - std::log(double(u1))) /
                                      std::max(1e-3, std::abs(std::log(double(u1)))));
    float sv, cv;
    sinCosTurnF(u2, &sv, &cv);
    sinCosWorst = std::max({sinCosWorst, std::abs(sv - std::sin(2 * M_PI * double(u2))),
                            std::abs(cv - std::cos(2 * M_PI * double(u2)))});
    const float c = float(k) * 0x1.0p-24f;
    acosWorst = std::max(acosWorst, std::abs(acosUnitF(c) - std::acos(double(c))));
  }
  for (float x : {1e-30f, 1e-7f, 0.70710677f, 0.7071068f, 1.f, 1.5f, 3e7f})
    logWorst = std::max(logWorst, std::abs(logPositiveF(x) - std::log(double(x))) /
                                      std::max(1e-3, std::abs(std::log(double(x)))));
  EXPECT_LT(logWorst, 5e-7);
  EXPECT_LT(sinCosWorst, 5e-7);
  EXPECT_LT(acosWorst, 5e-7);
  EXPECT_EQ(acosUnitF(1.f), 0.f);
  float sv, cv;
  sinCosTurnF(0.f, &sv, &cv);
  EXPECT_EQ(sv, 0.f);
  EXPECT_EQ(cv, 1.f);
}

// The batch (eight at a time with AVX2) gives gaussianPairAtF's bits, tail included.
TEST(Random, GaussianPairBatchIsBitForBitOneAtATime) {
  std::vector<uint64_t> index;
  for (uint64_t i = 0; i < 20011; ++i) index.push_back(3 * i * 7919 % 1000003);
  std::vector<float> a(index.size()), b(index.size()), c(index.size());
  gaussianPairsF(11, index.data(), index.size(), a.data(), b.data());
  gaussianPairsF(11, index.data(), index.size(), c.data(), nullptr);
  int differ = 0;
  for (size_t k = 0; k < index.size(); ++k) {
    const auto [g0, g1] = gaussianPairAtF(11, index[k]);
    differ += a[k] != g0 || b[k] != g1 || c[k] != g0;
  }
  EXPECT_EQ(differ, 0);
#if INHAND_FAST_MATH_AVX2
  if (!fastMathAvx2()) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar path was compared";
#endif
}

TEST(Pose, LookAtPutsTargetOnOpticalAxis) {
  Rng rng = makeRng(3);
  std::uniform_real_distribution<double> U(-1, 1);
  for (int i = 0; i < 200; ++i) {
    Vec3 eye(U(rng), U(rng), U(rng)), target(U(rng), U(rng), U(rng));
    Iso3 T_W_C = lookAt(eye, target);
    Vec3 p_C = T_W_C.inverse() * target;
    EXPECT_NEAR(p_C.x(), 0, 1e-12);
    EXPECT_NEAR(p_C.y(), 0, 1e-12);
    EXPECT_NEAR(p_C.z(), (target - eye).norm(), 1e-12);
    EXPECT_NEAR(T_W_C.linear().determinant(), 1.0, 1e-12);
  }
}

TEST(Pose, RowMajorRoundTripAndRejection) {
  auto rowMajor = [](const Iso3& P) { return isoJson(P).get<std::array<double, 16>>(); };
  Iso3 T = lookAt(Vec3(0.3, -0.2, 0.5), Vec3::Zero());
  std::string why;
  auto back = poseFromRowMajor(rowMajor(T), &why);
  ASSERT_TRUE(back);
  EXPECT_TRUE(back->isApprox(T, 1e-12));
  std::array<double, 16> singular{};
  singular[15] = 1;
  EXPECT_FALSE(poseFromRowMajor(singular, &why));
  EXPECT_NE(why.find("singular"), std::string::npos);
  auto reflect = rowMajor(Iso3::Identity());
  reflect[0] = -1;
  EXPECT_FALSE(poseFromRowMajor(reflect, &why));
  auto scaled = rowMajor(Iso3::Identity());
  scaled[5] = 2;
  EXPECT_FALSE(poseFromRowMajor(scaled, &why));
  EXPECT_NE(why.find("orthonormal"), std::string::npos);
  // A pose file's 7 significant digits (|RᵀR − I| ~1e-7..1e-4) is accepted as the nearest
  // rotation, within 1e-6 of the pose written; a rotation 5 % off is not; nor is a NaN.
  std::array<double, 16> rounded = rowMajor(T);
  for (double& v : rounded) v = std::stod(std::to_string(v).substr(0, 9));
  rounded[0] += 1e-4;  // and one entry off further, as real files have
  double deviation = 0;
  const auto near = poseFromRowMajor(rounded, &why, 1e-2, &deviation);
  ASSERT_TRUE(near) << why;
  EXPECT_GT(deviation, 5e-5);
  EXPECT_NEAR((near->linear().transpose() * near->linear() - Mat3::Identity()).norm(), 0, 1e-12);
  EXPECT_TRUE(near->isApprox(T, 1e-4));
  auto off = rowMajor(T);
  off[0] *= 1.05;
  EXPECT_FALSE(poseFromRowMajor(off, &why));
  auto nan = rowMajor(T);
  nan[6] = std::nan("");
  EXPECT_FALSE(poseFromRowMajor(nan, &why));
  EXPECT_NE(why.find("non-finite"), std::string::npos);
}

TEST(Pose, FibonacciSphereIsEven) {
  auto d = fibonacciSphere(500);
  ASSERT_EQ(d.size(), 500u);
  Vec3 mean = Vec3::Zero();
  for (const Vec3& v : d) {
    EXPECT_NEAR(v.norm(), 1.0, 1e-12);
    mean += v;
  }
  EXPECT_LT((mean / 500).norm(), 0.01);
}

TEST(Random, GaussianAtHasUnitMomentsAndIsReproducible) {
  double s = 0, s2 = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    double g = gaussianAt(42, i);
    s += g;
    s2 += g * g;
  }
  EXPECT_NEAR(s / n, 0.0, 0.01);
  EXPECT_NEAR(s2 / n, 1.0, 0.01);
  EXPECT_EQ(gaussianAt(42, 17), gaussianAt(42, 17));
  EXPECT_NE(gaussianAt(42, 17), gaussianAt(43, 17));
}

TEST(Random, GaussianPairsAreUncorrelatedWithUnitMoments) {
  double s[2] = {0, 0}, s2[2] = {0, 0}, cross = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    const auto [a, b] = gaussianPairAt(42, i);
    s[0] += a;
    s[1] += b;
    s2[0] += a * a;
    s2[1] += b * b;
    cross += a * b;
  }
  for (int k = 0; k < 2; ++k) {
    EXPECT_NEAR(s[k] / n, 0.0, 0.01);
    EXPECT_NEAR(s2[k] / n, 1.0, 0.01);
  }
  EXPECT_NEAR(cross / n, 0.0, 0.01);
  EXPECT_NEAR(gaussianPairAt(42, 17).first, gaussianAt(42, 17), 1e-12);
}

// The single-precision pair (the simulated sensor's per-pixel noise) against the double-precision
// one from the same hashes: within 1e-4 wherever the radius is below 3.7, never beyond 5.9,
// uncorrelated with unit moments, and gaussianAtF its first.
TEST(Random, SinglePrecisionGaussianPairsFollowTheDoubleOnes) {
  double s[2] = {0, 0}, s2[2] = {0, 0}, cross = 0, worst = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    const auto [a, b] = gaussianPairAtF(7, uint64_t(i));
    const auto [da, db] = gaussianPairAt(7, uint64_t(i));
    ASSERT_LE(std::hypot(a, b), 5.9f);
    if (std::hypot(da, db) < 3.7) worst = std::max({worst, std::abs(a - da), std::abs(b - db)});
    EXPECT_FLOAT_EQ(gaussianAtF(7, uint64_t(i)), a);
    s[0] += a;
    s[1] += b;
    s2[0] += double(a) * a;
    s2[1] += double(b) * b;
    cross += double(a) * b;
  }
  EXPECT_LT(worst, 1e-4);
  for (int k = 0; k < 2; ++k) {
    EXPECT_NEAR(s[k] / n, 0.0, 0.01);
    EXPECT_NEAR(s2[k] / n, 1.0, 0.01);
  }
  EXPECT_NEAR(cross / n, 0.0, 0.01);
}

TEST(FileUtil, AtomicWriteLeavesNothingOnFailure) {
  test::TempDir dir;
  fs::path p = dir.path() / "out.txt";
  EXPECT_THROW(writeFileAtomically(p,
                                   [](const fs::path& tmp) {
                                     std::ofstream(tmp) << "partial";
                                     throw Error("boom");
                                   }),
               Error);
  EXPECT_TRUE(fs::is_empty(dir.path()));
  writeTextAtomically(p, "whole");
  EXPECT_EQ(readTextFile(p), "whole");
}

TEST(FileUtil, StagedDirectoryCommitsOrVanishes) {
  test::TempDir dir;
  fs::path target = dir.path() / "frames";
  {
    StagedDirectory s(target);
    writeTextAtomically(s.path() / "a.txt", "x");
  }
  EXPECT_FALSE(fs::exists(target));
  EXPECT_TRUE(fs::is_empty(dir.path()));
  {
    StagedDirectory s(target);
    writeTextAtomically(s.path() / "a.txt", "x");
    s.commit();
  }
  EXPECT_TRUE(fs::exists(target / "a.txt"));
  EXPECT_THROW(StagedDirectory{target}, Error);  // not empty
}

TEST(Json, ErrorsNameFileAndField) {
  test::TempDir dir;
  fs::path p = dir.path() / "bad.json";
  writeTextAtomically(p, "{ \"a\": 1, ");
  try {
    readJsonFile(p);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.json"), std::string::npos);
  }
  Json j = Json::parse(R"({"n": "x"})");
  try {
    requireNumber(j, "n", "cfg.json: camera");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cfg.json: camera.n"), std::string::npos);
  }
}

// The persistent workers: every item exactly once, on both cores, over many calls; a nested call
// and calls from two threads at once (both fall back to fresh threads) do the same; an exception
// comes back to the caller and the workers go on working.
TEST(Parallel, ForThreadsRunsEveryItemOnceAndRethrows) {
  auto check = [](int n) {
    std::vector<std::atomic<int>> seen(static_cast<size_t>(n));
    parallelForThreads(0, n, [&](int i) { ++seen[size_t(i)]; });
    for (int i = 0; i < n; ++i)
      if (seen[size_t(i)] != 1) return false;
    return true;
  };
  for (int call = 0; call < 200; ++call) ASSERT_TRUE(check(1 + call % 37)) << call;
  // The work is shared: with a slow item first, another thread takes the rest.
  if (std::thread::hardware_concurrency() > 1) {
    std::mutex m;
    std::set<std::thread::id> ids;
    parallelForThreads(0, 8, [&](int i) {
      if (i == 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
      std::lock_guard<std::mutex> lock(m);
      ids.insert(std::this_thread::get_id());
    });
    EXPECT_GE(ids.size(), 2u);
  }
  std::atomic<int> inner{0};
  parallelForThreads(0, 4, [&](int) { parallelForThreads(0, 5, [&](int) { ++inner; }); });
  EXPECT_EQ(inner, 20);
  std::atomic<bool> ok1{false}, ok2{false};
  std::thread a([&] { ok1 = check(1000); }), b([&] { ok2 = check(1000); });
  a.join();
  b.join();
  EXPECT_TRUE(ok1 && ok2);
  std::atomic<int> ran{0};
  EXPECT_THROW(parallelForThreads(0, 1000,
                                  [&](int i) {
                                    ++ran;
                                    if (i == 3) throw std::runtime_error("item 3");
                                    // Long enough that the throw stops the rest well before
                                    // they are all handed out, even under a sanitizer.
                                    std::this_thread::sleep_for(std::chrono::microseconds(200));
                                  }),
               std::runtime_error);
  EXPECT_LT(ran, 1000);  // handing out stopped
  EXPECT_TRUE(check(100));
}
