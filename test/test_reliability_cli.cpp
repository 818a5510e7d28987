// Fault injection against the command line (docs/reliability.md, "Command line"): checkpoints,
// `umvs infer`'s arguments, broken or hostile files, resource bounds (`umvs train`'s run folders
// and arguments: test_train_cli_faults.cpp; SIGKILL: test_kill_faults.cpp). Each test checks the
// error a user sees and that nothing they had changed.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include "cli_test_util.h"
#include "test_util.h"
#include "unsup_mvs/core/depth_completion.h"
#include "unsup_mvs/core/memory_bounds.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/input_limits.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/plane_count.h"
#include "unsup_mvs/io/ply.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;
using test::contains;
using test::file_bytes;
using test::Result;
using test::run_umvs;
using test::scene;
using test::write_bytes;

// A random 8-plane model saved as our checkpoint.
std::string random_model(const std::string& path) {
  torch::manual_seed(1);
  MvsNetConfig cfg;
  cfg.num_depth = 8;
  MvsNet net(cfg);
  save_checkpoint(path, net);
  return path;
}

using test::kTrainFlags;

// ---------------------------------------------------------------------------------------------
// Checkpoints (item 8, and the ones that already behaved)

TEST(CheckpointFaults, NaNWeightsAreRefusedByInferAndTrainInit) {
  const std::string dir = test::temp_dir("nan_ckpt");
  const std::string data = scene("nan_data");
  torch::manual_seed(1);
  MvsNetConfig cfg;
  cfg.num_depth = 8;
  MvsNet net(cfg);
  {
    torch::NoGradGuard no_grad;
    net->named_parameters()["cost_regularization.conv3.conv.weight"].view({-1})[5] = NAN;
  }
  save_checkpoint(dir + "/nan.pt", net);
  EXPECT_THAT([&] { load_model(dir + "/nan.pt", torch::kCPU); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("'cost_regularization.conv3.conv.weight' has 1 non-finite values")));
  Result infer = run_umvs("infer --data " + data + " --checkpoint " + dir + "/nan.pt --out " + dir + "/infer --threads 1");
  EXPECT_EQ(infer.status, 1) << infer.output;
  EXPECT_TRUE(contains(infer.output, "non-finite")) << infer.output;
  EXPECT_FALSE(fs::exists(dir + "/infer/depth_est/00000000.pfm"));
  Result train = run_umvs("train --data " + data + kTrainFlags + " --steps 2 --init " + dir + "/nan.pt --out " + dir + "/run");
  EXPECT_EQ(train.status, 1) << train.output;
  EXPECT_TRUE(contains(train.output, "non-finite")) << train.output;
  EXPECT_FALSE(fs::exists(dir + "/run"));
}

TEST(CheckpointFaults, AFlippedByteFailsTheZipChecksum) {
  const std::string dir = test::temp_dir("crc_ckpt");
  const std::string good = random_model(dir + "/good.pt");
  std::string bytes = file_bytes(good);
  // A byte of tensor data (the weights are nearly all of the file; no zip record "PK.." near it):
  // flipped, it still unpickles, into other weights.
  size_t at = bytes.size() / 2;
  while (bytes.substr(at - 128, 256).find("PK") != std::string::npos) at += 4096;
  bytes[at] ^= 0x10;
  write_bytes(dir + "/flipped.pt", bytes);
  EXPECT_THAT([&] { load_model(dir + "/flipped.pt", torch::kCPU); },
              testing::ThrowsMessage<std::runtime_error>(testing::AllOf(testing::HasSubstr("CRC-32"), testing::HasSubstr("flipped.pt"))));
  const std::string data = scene("crc_data");
  Result r = run_umvs("infer --data " + data + " --checkpoint " + dir + "/flipped.pt --out " + dir + "/infer --threads 1");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "CRC-32")) << r.output;
  // The undamaged file still loads: the check does not refuse good checkpoints.
  EXPECT_NO_THROW(load_model(good, torch::kCPU));
}

TEST(CheckpointFaults, CorruptWrongArchitectureOversizedAndSpecialFilesAreRefused) {
  const std::string dir = test::temp_dir("bad_ckpt");
  const std::string data = scene("bad_ckpt_data");
  // Not a checkpoint at all.
  write_bytes(dir + "/garbage.pt", "this is not a checkpoint");
  Result garbage = run_umvs("infer --data " + data + " --checkpoint " + dir + "/garbage.pt --out " + dir + "/o1");
  EXPECT_EQ(garbage.status, 1);
  EXPECT_TRUE(contains(garbage.output, "not a readable model file")) << garbage.output;
  // Weights of another architecture: a state dict with a mis-shaped tensor (already refused).
  MvsNet net(MvsNetConfig{});
  c10::impl::GenericDict d(c10::StringType::get(), c10::TensorType::get());
  for (const auto& p : net->named_parameters()) d.insert(p.key(), p.value().detach().clone());
  for (const auto& b : net->named_buffers()) d.insert(b.key(), b.value().detach().clone());
  d.insert_or_assign("feature.feature.bias", torch::zeros({31}));
  const auto pickled = torch::pickle_save(c10::IValue(d));
  write_bytes(dir + "/other_arch.pt", std::string(pickled.begin(), pickled.end()));
  Result arch = run_umvs("infer --data " + data + " --checkpoint " + dir + "/other_arch.pt --out " + dir + "/o2");
  EXPECT_EQ(arch.status, 1);
  EXPECT_TRUE(contains(arch.output, "'feature.feature.bias' has shape [31]")) << arch.output;
  // Above the size bound (a sparse file: no disk used), a device and a FIFO: refused unread.
  { std::ofstream(dir + "/huge.pt"); }
  fs::resize_file(dir + "/huge.pt", kMaxCheckpointBytes + 1);
  Result huge = run_umvs("infer --data " + data + " --checkpoint " + dir + "/huge.pt --out " + dir + "/o3");
  EXPECT_EQ(huge.status, 1);
  EXPECT_TRUE(contains(huge.output, "more than the limit of 536870912 (512 MiB")) << huge.output;
  EXPECT_THAT([&] { load_model("/dev/zero", torch::kCPU); }, testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("is a device, not a regular file")));
  ASSERT_EQ(::mkfifo((dir + "/fifo.pt").c_str(), 0600), 0);
  EXPECT_THAT([&] { load_model(dir + "/fifo.pt", torch::kCPU); }, testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("is a FIFO")));
  EXPECT_FALSE(fs::exists(dir + "/o1/depth_est/00000000.pfm") || fs::exists(dir + "/o2/depth_est/00000000.pfm"));
}

// ---------------------------------------------------------------------------------------------
// umvs infer: depth ranges (item 9) and resource bounds

TEST(InferArguments, ImpossibleDepthRangesAreRefusedAndTheUsedRangeIsSaid) {
  const std::string dir = test::temp_dir("range");
  const std::string data = scene("range_data");
  const std::string model = random_model(dir + "/model.pt");
  const std::string common = "infer --data " + data + " --checkpoint " + model + " --threads 1 --ref 0 --out " + dir;
  for (const std::string bad : {" --depth-min -1 --depth-max -0.5", " --depth-min 5 --depth-max 2", " --depth-max -3",
                                " --depth-min nan"}) {
    Result r = run_umvs(common + "/bad" + bad);
    EXPECT_EQ(r.status, 2) << bad << ": " << r.output;
    EXPECT_TRUE(contains(r.output, "--depth-m")) << r.output;
    EXPECT_FALSE(fs::exists(dir + "/bad")) << bad;
  }
  // Only the near end given, beyond the cam file's far end: the mix is impossible, said per source.
  const MvsCam cam = read_cam_file(data + "/cams/00000000_cam.txt");
  const double beyond = cam.resolved_depth_max(8) + 1.0;
  Result mixed = run_umvs(common + "/mixed --depth-min " + std::to_string(beyond));
  EXPECT_EQ(mixed.status, 2) << mixed.output;
  EXPECT_TRUE(contains(mixed.output, "(from --depth-min)") && contains(mixed.output, "(from its cam file)")) << mixed.output;
  // A valid override: used, and said so next to the cam file's range.
  Result ok = run_umvs(common + "/ok --depth-min 0.5 --depth-max 6");
  ASSERT_EQ(ok.status, 0) << ok.output;
  EXPECT_TRUE(contains(ok.output, "0.5 (from --depth-min) .. 6 (from --depth-max); its cam file gives")) << ok.output;
  EXPECT_DOUBLE_EQ(read_cam_file(dir + "/ok/cams/00000000_cam.txt").depth_min, 0.5);
}

TEST(InferArguments, BadSourceOptionsAreRefusedByName) {
  const std::string dir = test::temp_dir("source_options");
  const std::string data = scene("source_options_data");
  const std::string model = random_model(dir + "/model.pt");
  const std::string common = "infer --data " + data + " --checkpoint " + model + " --threads 1 --ref 0 --out " + dir + "/bad";
  for (const std::string bad : {" --source-rotation-search -1", " --source-rotation-search nan",
                                " --source-combination bogus", " --complete-below-confidence 1",
                                " --complete-below-confidence -0.5"}) {
    Result r = run_umvs(common + bad);
    EXPECT_EQ(r.status, 2) << bad << ": " << r.output;
    EXPECT_TRUE(contains(r.output, bad.substr(1, bad.find(' ', 1) - 1)) || contains(r.output, "bogus")) << r.output;
    EXPECT_FALSE(fs::exists(dir + "/bad")) << bad;
  }
}

// Completion is on by default at the recommended floor, and 0 gives the network's own depth; the
// confidence maps are the network's either way.
TEST(InferArguments, CompletionIsOnByDefaultAndZeroTurnsItOff) {
  const std::string dir = test::temp_dir("completion_default");
  const std::string data = scene("completion_default_data", 160, 128);
  const std::string common = "infer --data " + data + " --checkpoint " + std::string(UMVS_SOURCE_DIR) +
                             "/models/unsup_mvsnet.pt --threads 2 --ref 0 --out " + dir;
  const Result by_default = run_umvs(common + "/default");
  ASSERT_EQ(by_default.status, 0) << by_default.output;
  EXPECT_TRUE(contains(by_default.output, "completed")) << by_default.output;
  ASSERT_EQ(run_umvs(common + "/floor --complete-below-confidence 0.7").status, 0);
  const Result off = run_umvs(common + "/off --complete-below-confidence 0");
  ASSERT_EQ(off.status, 0) << off.output;
  EXPECT_FALSE(contains(off.output, "completed")) << off.output;

  const std::string depth = "/depth_est/00000000.pfm", confidence = "/confidence/00000000.pfm";
  EXPECT_EQ(file_bytes(dir + "/default" + depth), file_bytes(dir + "/floor" + depth));
  EXPECT_EQ(file_bytes(dir + "/default" + confidence), file_bytes(dir + "/off" + confidence));
  const torch::Tensor completed = read_pfm(dir + "/default" + depth), own = read_pfm(dir + "/off" + depth);
  const torch::Tensor unsure = read_pfm(dir + "/off" + confidence) < kRecommendedCompletionConfidence;
  const double unsure_share = unsure.to(torch::kFloat).mean().item<double>();
  ASSERT_GT(unsure_share, 0.05) << "the scene must have unsure pixels for this test";
  ASSERT_LT(unsure_share, 0.95) << "and confident ones to complete them from";
  const torch::Tensor moved = ((completed - own).abs() > 1e-3 * own).masked_select(unsure);
  EXPECT_GT(moved.to(torch::kFloat).mean().item<double>(), 0.5) << "most unsure pixels get a completed depth";
}

// The source combination is auto by default: an untrained model is unsure of every map, so the
// default adds most_confident's per-source passes and says so; variance keeps the one pass.
TEST(InferArguments, SourcesAreAutoByDefault) {
  const std::string dir = test::temp_dir("sources_default");
  const std::string data = scene("sources_default_data");
  const std::string model = random_model(dir + "/model.pt");
  const std::string common = "infer --data " + data + " --checkpoint " + model + " --threads 1 --ref 0 --out " + dir;
  const Result by_default = run_umvs(common + "/default");
  ASSERT_EQ(by_default.status, 0) << by_default.output;
  EXPECT_TRUE(contains(by_default.output, "sources also alone")) << by_default.output;
  ASSERT_EQ(run_umvs(common + "/most_confident --source-combination most_confident").status, 0);
  const Result variance = run_umvs(common + "/variance --source-combination variance");
  ASSERT_EQ(variance.status, 0) << variance.output;
  EXPECT_FALSE(contains(variance.output, "sources also alone")) << variance.output;
  const std::string depth = "/depth_est/00000000.pfm";
  EXPECT_EQ(file_bytes(dir + "/default" + depth), file_bytes(dir + "/most_confident" + depth));
  EXPECT_NE(file_bytes(dir + "/default" + depth), file_bytes(dir + "/variance" + depth));
}

TEST(InferArguments, PlaneCountFollowsTheInputSizeNotTheCheckpoint) {
  EXPECT_EQ(default_plane_count(640), 128);   // MVSNet training
  EXPECT_EQ(default_plane_count(1600), 192);  // MVSNet on DTU
  EXPECT_EQ(default_plane_count(320), 64);
  EXPECT_EQ(default_plane_count(96), 16);
  const std::string dir = test::temp_dir("planes");
  const std::string data = scene("planes_data");  // 96x64
  torch::manual_seed(1);
  MvsNetConfig cfg;
  cfg.num_depth = 32;  // as if fine-tuned with 32 planes
  MvsNet net(cfg);
  save_checkpoint(dir + "/model32.pt", net);
  const std::string common = "infer --data " + data + " --checkpoint " + dir + "/model32.pt --threads 1 --ref 0 --out ";
  Result by_default = run_umvs(common + dir + "/default");
  ASSERT_EQ(by_default.status, 0) << by_default.output;
  EXPECT_TRUE(contains(by_default.output, "depth planes: 16 planes (default for a 96x64 network input")) << by_default.output;
  EXPECT_TRUE(contains(by_default.output, "the checkpoint was trained with 32")) << by_default.output;
  EXPECT_EQ(read_cam_file(dir + "/default/cams/00000000_cam.txt").depth_num, 16);
  Result given = run_umvs(common + dir + "/given --num-depth 24");
  ASSERT_EQ(given.status, 0) << given.output;
  EXPECT_TRUE(contains(given.output, "depth planes: 24 planes (--num-depth; the checkpoint was trained with 32)"))
      << given.output;
  EXPECT_EQ(read_cam_file(dir + "/given/cams/00000000_cam.txt").depth_num, 24);
}

TEST(ResourceBounds, PlanesVolumesAndImagesAboveTheBoundsAreRefused) {
  // The estimates: MVSNet's DTU evaluation size fits, four times its pixels do not.
  EXPECT_LT(estimated_inference_bytes(1600, 1184, 192, 3), kMaxInferenceBytes);
  EXPECT_THROW(check_inference_memory(3200, 2368, 192, 3), std::invalid_argument);
  EXPECT_NO_THROW(check_training_memory(640, 512, 128, 3, 6, 1));
  EXPECT_THROW(check_training_memory(640, 512, 128, 3, 6, 8), std::invalid_argument);
  EXPECT_THROW(check_inference_memory(64, 64, kMaxDepthPlanes + 8, 3), std::invalid_argument);

  const std::string dir = test::temp_dir("bounds");
  const std::string data = scene("bounds_data");
  const std::string model = random_model(dir + "/model.pt");
  Result planes = run_umvs("infer --data " + data + " --checkpoint " + model + " --num-depth 2048 --out " + dir + "/o");
  EXPECT_EQ(planes.status, 2) << planes.output;
  EXPECT_TRUE(contains(planes.output, "2048 depth planes, more than the 1024 accepted")) << planes.output;
  EXPECT_FALSE(fs::exists(dir + "/o"));
  Result big = run_umvs("train --data " + data + " --width 2048 --height 1536 --num-depth 256 --out " + dir + "/t");
  EXPECT_EQ(big.status, 2) << big.output;
  EXPECT_TRUE(contains(big.output, "of memory, more than the 12.0 GiB accepted")) << big.output;
  EXPECT_FALSE(fs::exists(dir + "/t"));

  // A 60-byte PNG that claims 100000 x 100000 pixels: refused from its header, never decoded.
  std::string png("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR", 16);
  const unsigned char size[8] = {0x00, 0x01, 0x86, 0xA0, 0x00, 0x01, 0x86, 0xA0};
  png.append(reinterpret_cast<const char*>(size), 8);
  png.append(std::string("\x08\x02\0\0\0", 5) + std::string(27, '\0'));
  write_bytes(dir + "/bomb.png", png);
  EXPECT_THAT([&] { read_image_rgb8(dir + "/bomb.png"); }, testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("100000x100000")));
}

// ---------------------------------------------------------------------------------------------
// Readers and umvs eval cloud (item 10)

std::string ply_header(const std::string& format, uint64_t count) {
  return "ply\nformat " + format + " 1.0\nelement vertex " + std::to_string(count) +
         "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
}

TEST(RenderArguments, ACamIsDrawnAtItsImagesSizeAndAnotherSizeIsRefused) {
  const std::string data = test::scene("render_cam", 96, 64, 3);
  const std::string dir = test::temp_dir("render_cam_out");
  // Points on a plane 2 units in front of view 0, covering its whole image.
  const std::string cam_file = data + "/cams/00000000_cam.txt";
  const Camera cam = read_cam_file(cam_file).camera;
  PointCloud cloud;
  for (int v = 0; v < 64; v += 2) {
    for (int u = 0; u < 96; u += 2) cloud.points.push_back(cam.backproject(u, v, 2.0).cast<float>());
  }
  write_ply(dir + "/plane.ply", cloud);

  // No size given: the picture has the size of the view's image (96x64), so the plane fills it.
  auto r = test::run_umvs("render --cloud " + dir + "/plane.ply --cam " + cam_file + " --out " + dir + "/a.png");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_THAT(r.output, testing::HasSubstr("(96x64)"));
  const auto picture = read_image_rgb8(dir + "/a.png");
  ASSERT_EQ(picture.size(0), 64);
  ASSERT_EQ(picture.size(1), 96);
  // Every part of the picture is drawn (background is white, points grey), the far corner as much
  // as the near one; drawn into a 4x larger picture, only the top-left quarter would be.
  const auto drawn = (picture != 255).any(-1).to(torch::kFloat);
  EXPECT_GT(drawn.slice(0, 32, 64).slice(1, 48, 96).mean().item<double>(), 0.9);
  EXPECT_GT(drawn.slice(0, 0, 32).slice(1, 0, 48).mean().item<double>(), 0.9);

  // Another size than the cam file's image: refused with the reason, nothing written.
  r = test::run_umvs("render --cloud " + dir + "/plane.ply --cam " + cam_file + " --width 384 --height 256 --out " + dir +
                     "/b.png");
  EXPECT_NE(r.status, 0);
  EXPECT_THAT(r.output, testing::HasSubstr("principal point"));
  EXPECT_THAT(r.output, testing::HasSubstr("384x256"));
  EXPECT_FALSE(std::filesystem::exists(dir + "/b.png"));
  // The same size stated explicitly, or drawn larger with --scale, is fine.
  r = test::run_umvs("render --cloud " + dir + "/plane.ply --cam " + cam_file + " --width 96 --height 64 --scale 4 --out " +
                     dir + "/c.png");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_THAT(r.output, testing::HasSubstr("(384x256)"));
}

TEST(ReaderFaults, EmptyAndNonFiniteCloudsAreRefusedWithTheReason) {
  const std::string dir = test::temp_dir("clouds");
  PointCloud gt;
  for (int i = 0; i < 50; ++i) gt.points.emplace_back(0.01f * i, 0.f, 1.f);
  write_ply(dir + "/gt.ply", gt);
  write_ply(dir + "/empty.ply", PointCloud());
  PointCloud nan_cloud = gt;
  nan_cloud.points[7].y() = NAN;
  write_ply(dir + "/nan_binary.ply", nan_cloud);
  write_bytes(dir + "/nan_ascii.ply", ply_header("ascii", 2) + "0 0 1\n0 nan 1\n");
  struct Case {
    std::string file, reason;
  };
  for (const auto& c : {Case{"empty.ply", "has no points"}, Case{"nan_binary.ply", "vertex 7 has a non-finite coordinate"},
                        Case{"nan_ascii.ply", "vertex 1 has a non-finite coordinate"}}) {
    Result r = run_umvs("eval cloud --est " + dir + "/" + c.file + " --gt " + dir + "/gt.ply");
    EXPECT_EQ(r.status, 1) << c.file << ": " << r.output;
    EXPECT_TRUE(contains(r.output, c.reason)) << c.file << ": " << r.output;
    EXPECT_FALSE(contains(r.output, "nan ")) << r.output;
  }
  Result ok = run_umvs("eval cloud --est " + dir + "/gt.ply --gt " + dir + "/gt.ply --json", "2>/dev/null");
  EXPECT_EQ(ok.status, 0) << ok.output;
  const auto metrics = nlohmann::json::parse(ok.output);
  EXPECT_EQ(metrics.at("accuracy_mean"), 0.0) << ok.output;
  EXPECT_EQ(metrics.at("est_points"), 50) << ok.output;
}

TEST(ReaderFaults, CountsClaimedByHeadersAreBoundedByTheFileSize) {
  const std::string dir = test::temp_dir("claims");
  auto refused = [](const std::function<void()>& read, const std::string& reason) {
    EXPECT_THAT(read, testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr(reason)));
  };
  // 5e9 vertices claimed, 3 present (binary and ASCII): refused before any allocation.
  write_bytes(dir + "/binary.ply", ply_header("binary_little_endian", 5000000000ull) + std::string(36, '\0'));
  write_bytes(dir + "/ascii.ply", ply_header("ascii", 5000000000ull) + "0 0 1\n0 1 1\n1 0 1\n");
  refused([&] { read_ply(dir + "/binary.ply"); }, "vertex count: the header claims 5000000000");
  refused([&] { read_ply(dir + "/ascii.ply"); }, "vertex count: the header claims 5000000000");
  std::string negative = ply_header("ascii", 1);
  negative.replace(negative.find("vertex 1"), 8, "vertex -1");
  write_bytes(dir + "/negative.ply", negative + "0 0 1\n");
  refused([&] { read_ply(dir + "/negative.ply"); }, "malformed element line");
  Result eval = run_umvs("eval cloud --est " + dir + "/binary.ply --gt " + dir + "/ascii.ply");
  EXPECT_EQ(eval.status, 1);
  EXPECT_TRUE(contains(eval.output, "the header claims 5000000000")) << eval.output;
  // pair.txt claiming 1.5e9 views, or one view with 2e9 sources.
  write_bytes(dir + "/pair.txt", "1500000000\n0\n1 1 1.0\n");
  refused([&] { read_pair_file(dir + "/pair.txt"); }, "number of views: the header claims 1500000000");
  write_bytes(dir + "/pair2.txt", "1\n0\n2000000000 1 1.0\n");
  refused([&] { read_pair_file(dir + "/pair2.txt"); }, "number of sources of view 0: the header claims 2000000000");
  // NPY and PFM whose shapes claim far more than the file holds (and would overflow 64 bits).
  std::string npy_header = "{'descr': '<f4', 'fortran_order': False, 'shape': (100000000000, 100000000000, 100000000000), }";
  npy_header += std::string(63 - (10 + npy_header.size()) % 64, ' ') + "\n";
  std::string npy("\x93NUMPY\x01\x00", 8);
  npy += static_cast<char>(npy_header.size() & 0xff);
  npy += static_cast<char>(npy_header.size() >> 8);
  write_bytes(dir + "/a.npy", npy + npy_header + std::string(16, '\0'));
  refused([&] { read_npy(dir + "/a.npy"); }, "array dimension: the header claims 100000000000");
  write_bytes(dir + "/a.pfm", "Pf\n100000 100000\n-1\n" + std::string(16, '\0'));
  refused([&] { read_pfm(dir + "/a.pfm"); }, "PFM values: the header claims 10000000000");
  // A cam file whose DEPTH_NUM is no plane count.
  write_bytes(dir + "/cam.txt", "extrinsic\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n\nintrinsic\n100 0 32\n0 100 32\n0 0 1\n\n"
                                "1 0.1 1e12\n");
  refused([&] { read_cam_file(dir + "/cam.txt"); }, "DEPTH_NUM must be a whole number");
  // Readers refuse what is not a regular file instead of blocking on it or reading it forever.
  ASSERT_EQ(::mkfifo((dir + "/fifo.ply").c_str(), 0600), 0);
  refused([&] { read_ply(dir + "/fifo.ply"); }, "is a FIFO");
  refused([&] { read_pfm("/dev/zero"); }, "is a device");
}

}  // namespace
}  // namespace umvs
