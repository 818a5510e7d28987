#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <fstream>
#include <iomanip>
#include <sstream>

#include "test_util.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/inference_folder.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/ply.h"
#include "unsup_mvs/io/run_folder.h"

namespace umvs {
namespace {

using test::write_text;

TEST(ArrayIo, NpyRoundTrip) {
  const auto dir = test::temp_dir("npy");
  auto a = torch::rand({3, 4, 5});
  write_npy(dir + "/a.npy", a);
  EXPECT_TRUE(torch::equal(read_npy(dir + "/a.npy"), a));
  auto b = torch::randint(0, 255, {7, 2}).to(torch::kUInt8);
  write_npy(dir + "/b.npy", b);
  EXPECT_TRUE(torch::equal(read_npy(dir + "/b.npy"), b));
  auto s = torch::arange(6, torch::kInt64);
  write_npy(dir + "/s.npy", s);
  EXPECT_TRUE(torch::equal(read_npy(dir + "/s.npy"), s));
  write_text(dir + "/bad.npy", "hello");
  EXPECT_THROW(read_npy(dir + "/bad.npy"), std::runtime_error);
}

TEST(ArrayIo, PfmRoundTripKeepsRowOrder) {
  const auto dir = test::temp_dir("pfm");
  auto a = torch::arange(12, torch::kFloat32).view({3, 4});
  write_pfm(dir + "/a.pfm", a);
  auto r = read_pfm(dir + "/a.pfm");
  EXPECT_TRUE(torch::equal(r, a));
  // The first stored row is the bottom image row.
  std::ifstream in(dir + "/a.pfm", std::ios::binary);
  std::string line;
  for (int i = 0; i < 3; ++i) std::getline(in, line);
  float first;
  in.read(reinterpret_cast<char*>(&first), 4);
  EXPECT_EQ(first, 8.0f);
  write_text(dir + "/short.pfm", "Pf\n4 3\n-1\nabc");
  EXPECT_THROW(read_pfm(dir + "/short.pfm"), std::runtime_error);
}

TEST(Ply, BinaryRoundTripWithAttributes) {
  const auto dir = test::temp_dir("ply");
  PointCloud c;
  for (int i = 0; i < 5; ++i) {
    c.points.emplace_back(i, 2.0f * i, -0.5f * i);
    c.colors.push_back({static_cast<uint8_t>(i), 10, 200});
    c.confidence.push_back(0.1f * i);
    c.num_views.push_back(static_cast<uint8_t>(i + 2));
  }
  write_ply(dir + "/c.ply", c);
  const PointCloud r = read_ply(dir + "/c.ply");
  ASSERT_EQ(r.size(), 5u);
  EXPECT_EQ(r.points[3], c.points[3]);
  EXPECT_EQ(r.colors[4], c.colors[4]);
  EXPECT_FLOAT_EQ(r.confidence[2], 0.2f);
  EXPECT_EQ(r.num_views[1], 3);
  write_text(dir + "/a.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
                             "property double z\nproperty int flags\nend_header\n1 2 3 0\n4 5 6 1\n");
  const PointCloud a = read_ply(dir + "/a.ply");
  ASSERT_EQ(a.size(), 2u);
  EXPECT_FLOAT_EQ(a.points[1].z(), 6.0f);
  EXPECT_FALSE(a.has_colors());
}

TEST(AtomicWrite, FailedWriteKeepsTheOldFile) {
  const auto dir = test::temp_dir("atomic");
  PointCloud c;
  c.points.emplace_back(1, 2, 3);
  write_ply(dir + "/keep.ply", c);
  PointCloud bad;
  bad.points.emplace_back(0, 0, 0);
  // An unwritable target folder (a file in the way) fails without touching keep.ply.
  write_text(dir + "/blocker", "x");
  EXPECT_THROW(write_ply(dir + "/blocker/out.ply", bad), std::runtime_error);
  EXPECT_EQ(read_ply(dir + "/keep.ply").points[0], c.points[0]);
}

TEST(MvsFolder, CamFileRoundTripAndErrors) {
  const auto dir = test::temp_dir("cam");
  MvsCam cam;
  cam.camera.K << 361.5, 0, 160.25, 0, 362.0, 128.5, 0, 0, 1;
  cam.camera.T_cam_world.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  cam.camera.T_cam_world.topRightCorner<3, 1>() = Eigen::Vector3d(0.1, 0.2, 0.3);
  cam.depth_min = 425;
  cam.depth_interval = 2.5;
  cam.depth_num = 192;
  write_cam_file(dir + "/ok_cam.txt", cam);
  const MvsCam r = read_cam_file(dir + "/ok_cam.txt");
  EXPECT_TRUE(r.camera.K.isApprox(cam.camera.K, 1e-12));
  EXPECT_TRUE(r.camera.T_cam_world.isApprox(cam.camera.T_cam_world, 1e-10));
  EXPECT_DOUBLE_EQ(r.resolved_depth_max(128), 425 + 2.5 * 191);

  auto expect_error = [&](const std::string& text, const std::string& needle) {
    write_text(dir + "/bad_cam.txt", text);
    EXPECT_THAT([&] { read_cam_file(dir + "/bad_cam.txt"); },
                testing::ThrowsMessage<std::runtime_error>(
                    testing::AllOf(testing::HasSubstr(needle), testing::HasSubstr("bad_cam.txt"))))
        << text;
  };
  const std::string ext = "extrinsic\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";
  const std::string intr = "intrinsic\n100 0 50\n0 100 40\n0 0 1\n";
  expect_error("intrinsic\n", "expected 'extrinsic'");
  expect_error(ext + "intrinsic\n100 0 50\n0 abc 40\n0 0 1\n", "not a number");
  expect_error(ext + "intrinsic\n100 0 50\n0 nan 40\n0 0 1\n", "non-finite");
  expect_error(ext + intr + "2.0 0.01 128 1.0\n", "impossible depth range");
  expect_error("extrinsic\n2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n" + intr + "1 0.1\n", "rotation");
  expect_error(ext + "intrinsic\n100 0 50\n0 100 40\n", "file ends");
}

// 7-Scenes writes its poses with 8 digits: R^T R - I reaches 1e-4. Such a file is read as the
// nearest rotation; a matrix further off than kMaxRotationRepairError is still refused.
TEST(MvsFolder, AlmostRotationsAreRepairedAndFarOnesRefused) {
  const auto dir = test::temp_dir("cam_repair");
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  auto write_with = [&](const Eigen::Matrix3d& M) {
    std::ostringstream text;
    text << std::setprecision(17) << "extrinsic\n";
    for (int r = 0; r < 3; ++r) text << M(r, 0) << " " << M(r, 1) << " " << M(r, 2) << " " << 0.1 * r << "\n";
    text << "0 0 0 1\nintrinsic\n585 0 320\n0 585 240\n0 0 1\n0.5 0.01 128\n";
    write_text(dir + "/cam.txt", text.str());
  };
  Eigen::Matrix3d noisy = R;
  noisy(0, 1) += 1.5e-4;  // as rounding of the 7-Scenes files leaves it
  noisy(2, 0) -= 1.0e-4;
  ASSERT_GT(orthonormality_error(noisy), 1e-4);
  write_with(noisy);
  const Camera repaired = read_cam_file(dir + "/cam.txt").camera;
  EXPECT_LT(orthonormality_error(repaired.R()), 1e-12);
  EXPECT_NEAR(repaired.R().determinant(), 1.0, 1e-12);
  EXPECT_LT(rotation_angle(repaired.R(), R), 2e-4);  // the nearest rotation, not some other one
  EXPECT_DOUBLE_EQ(repaired.t().y(), 0.1);           // the translation as written

  // Within validate()'s tolerance a file is read as written, bit for bit (parity with other code
  // reading the same cam files depends on it).
  Eigen::Matrix3d nearly = R;
  nearly(0, 1) += 2e-5;
  write_with(nearly);
  EXPECT_EQ(read_cam_file(dir + "/cam.txt").camera.R(), nearly);

  Eigen::Matrix3d far = R;
  far(0, 0) += 0.05;
  write_with(far);
  EXPECT_THAT([&] { read_cam_file(dir + "/cam.txt"); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("not a proper rotation")));
  write_with(-R);  // a reflection is no rotation however orthonormal
  EXPECT_THAT([&] { read_cam_file(dir + "/cam.txt"); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("not a proper rotation")));
}

TEST(MvsFolder, PairFileRoundTripAndMissingParts) {
  const auto dir = test::temp_dir("pair");
  std::vector<ViewPair> pairs = {{0, {1, 2}, {3.5, 1.25}}, {1, {0}, {3.5}}};
  write_pair_file(dir + "/pair.txt", pairs);
  const auto r = read_pair_file(dir + "/pair.txt");
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].sources, (std::vector<int>{1, 2}));
  EXPECT_DOUBLE_EQ(r[0].scores[1], 1.25);
  EXPECT_THAT([&] { MvsFolder folder(dir); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("images/")));
}

TEST(InferenceFolder, OneLayoutForInferFuseAndEval) {
  const std::string root = test::temp_dir("inference_folder");
  const InferenceFolder f(root + "/out");
  EXPECT_FALSE(InferenceFolder::holds(f.root()));
  f.create();
  EXPECT_TRUE(InferenceFolder::holds(f.root()));
  EXPECT_EQ(f.depth_path(7), root + "/out/depth_est/00000007.pfm");
  EXPECT_EQ(f.depth_preview_path(7), root + "/out/depth_est/00000007.png");
  EXPECT_EQ(f.confidence_path(7), root + "/out/confidence/00000007.pfm");
  EXPECT_EQ(f.confidence_preview_path(7), root + "/out/confidence/00000007.png");
  EXPECT_EQ(f.cam_path(7), root + "/out/cams/00000007_cam.txt");
  EXPECT_EQ(f.image_path(7), root + "/out/images/00000007.png");
  EXPECT_EQ(f.pair_file(), root + "/out/pair.txt");
  // Images are looked up as MVSNet folders name them, .jpg before .png.
  std::ofstream(f.images_dir() + "/00000003.png") << "x";
  EXPECT_EQ(find_view_image(f.images_dir(), 3), f.images_dir() + "/00000003.png");
  std::ofstream(f.images_dir() + "/00000003.jpg") << "x";
  EXPECT_EQ(find_view_image(f.images_dir(), 3), f.images_dir() + "/00000003.jpg");
  EXPECT_THAT([&] { find_view_image(f.images_dir(), 4); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("no image for view 4 in " + f.images_dir())));
}

TEST(RunTables, WriterAndReadersShareOneDefinition) {
  const std::string dir = test::temp_dir("run_tables");
  EXPECT_EQ(csv_header(train_log_columns()).rfind("step,total,photometric,", 0), 0u);
  EXPECT_EQ(csv_header(eval_columns()).rfind("checkpoint,tuples,photometric,", 0), 0u);
  // A training step with validation and one without: written and read back through the same table.
  TrainLogRow validated;
  validated.step = 7;
  validated.total = 0.5;
  validated.lr = 1e-3;
  validated.val_abs_err = 0.25;
  TrainLogRow plain;
  plain.step = 8;
  plain.total = 0.4;
  const std::string line = format_csv_row(plain);
  EXPECT_EQ(std::count(line.begin(), line.end(), ','), static_cast<long>(train_log_columns().size() - 1)) << line;
  std::ofstream(dir + "/log.csv") << csv_header(train_log_columns()) << "\n"
                                  << format_csv_row(validated) << "\n"
                                  << line << "\n\n";
  const auto rows = read_csv_rows(dir + "/log.csv");
  ASSERT_EQ(rows.size(), 2u);
  const TrainLogRow first = train_log_row(rows[0]), last = train_log_row(rows[1]);
  EXPECT_EQ(first.step, 7);
  EXPECT_DOUBLE_EQ(*first.val_abs_err, 0.25);
  EXPECT_DOUBLE_EQ(*first.lr, 1e-3);
  EXPECT_FALSE(first.val_total.has_value());
  EXPECT_EQ(last.step, 8);
  EXPECT_DOUBLE_EQ(*last.total, 0.4);
  EXPECT_FALSE(last.val_abs_err.has_value());  // not measured at that step
  EXPECT_FALSE(last.supervised.has_value());   // the trailing empty cell
  CsvRow row;
  ASSERT_TRUE(read_last_csv_row(dir + "/log.csv", &row));
  EXPECT_EQ(row.number("step"), 8.0);
  EXPECT_FALSE(row.number("no_such_column").has_value());

  EvalRow eval;
  eval.checkpoint = "/models/a.pt";
  eval.photometric = 0.125;
  eval.consistent = 0.5;
  std::ofstream(dir + "/eval.csv") << csv_header(eval_columns()) << "\n" << format_csv_row(eval) << "\n";
  ASSERT_TRUE(read_last_csv_row(dir + "/eval.csv", &row));
  const EvalRow read = eval_row(row);
  EXPECT_EQ(read.checkpoint, "/models/a.pt");
  EXPECT_DOUBLE_EQ(*read.photometric, 0.125);
  EXPECT_DOUBLE_EQ(*read.consistent, 0.5);
  EXPECT_FALSE(read.abs_err.has_value());
  eval.checkpoint = "a,b.pt";
  EXPECT_THAT([&] { format_csv_row(eval); },
              testing::ThrowsMessage<std::invalid_argument>(testing::HasSubstr("'a,b.pt' has a comma")));

  std::ofstream(dir + "/bad.csv") << "step,photometric\n1,0.1x\n,0.2\n";
  const auto bad = read_csv_rows(dir + "/bad.csv");
  EXPECT_FALSE(bad.at(0).number("photometric").has_value());
  EXPECT_THAT([&] { train_log_row(bad.at(1)); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("without a step")));
  EXPECT_FALSE(read_last_csv_row(dir + "/missing.csv", &row));
  EXPECT_THAT([&] { read_csv_rows(dir + "/missing.csv"); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("cannot read " + dir + "/missing.csv")));
  std::ofstream(dir + "/header_only.csv") << "step,total\n";
  EXPECT_FALSE(read_last_csv_row(dir + "/header_only.csv", &row));
}

TEST(Checkpoint, RoundTripAndMismatchIsNamed) {
  const auto dir = test::temp_dir("ckpt");
  MvsNetConfig cfg;
  cfg.num_depth = 32;
  cfg.depth_sampling = DepthSampling::kUniformInverseDepth;
  cfg.feature_warp = FeatureWarp::kMvsNetPytorch;
  torch::manual_seed(3);
  MvsNet net(cfg);
  CheckpointMeta meta;
  meta.step = 42;
  meta.metrics["val_loss"] = 0.25;
  meta.optimizer_state = std::string("\x00\x01\xff", 3);
  save_checkpoint(dir + "/a.pt", net, meta);
  auto loaded = load_model(dir + "/a.pt", torch::kCPU);
  EXPECT_EQ(loaded.format, "unsup_mvs");
  EXPECT_EQ(loaded.model->config().num_depth, 32);
  EXPECT_EQ(loaded.model->config().depth_sampling, DepthSampling::kUniformInverseDepth);
  EXPECT_EQ(loaded.model->config().feature_warp, FeatureWarp::kMvsNetPytorch);
  EXPECT_EQ(loaded.meta.step, 42);
  EXPECT_EQ(loaded.meta.optimizer_state, meta.optimizer_state);
  EXPECT_DOUBLE_EQ(loaded.meta.metrics.at("val_loss"), 0.25);
  auto p1 = net->named_parameters()["cost_regularization.conv3.conv.weight"];
  auto p2 = loaded.model->named_parameters()["cost_regularization.conv3.conv.weight"];
  EXPECT_TRUE(torch::equal(p1, p2));
  net->set_feature_warp(FeatureWarp::kExact);
  save_checkpoint(dir + "/exact.pt", net, meta);
  EXPECT_EQ(load_model(dir + "/exact.pt", torch::kCPU).model->config().feature_warp, FeatureWarp::kExact);
  // A checkpoint written before the field existed was trained with MVSNet_pytorch's warp.
  {
    std::ifstream in(dir + "/exact.pt", std::ios::binary);
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    auto root = torch::pickle_load(bytes).toGenericDict();
    ASSERT_EQ(root.at("config").toGenericDict().erase("feature_warp"), 1u);
    const std::vector<char> old = torch::pickle_save(c10::IValue(root));
    std::ofstream(dir + "/old.pt", std::ios::binary).write(old.data(), static_cast<std::streamsize>(old.size()));
  }
  EXPECT_EQ(load_model(dir + "/old.pt", torch::kCPU).model->config().feature_warp, FeatureWarp::kMvsNetPytorch);

  MvsNetConfig want_refine = cfg;
  want_refine.refine = true;
  EXPECT_THAT([&] { load_model(dir + "/a.pt", torch::kCPU, &want_refine); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("refinement")));
  write_text(dir + "/corrupt.pt", "this is not a checkpoint");
  EXPECT_THAT([&] { load_model(dir + "/corrupt.pt", torch::kCPU); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("corrupt.pt")));
}

TEST(Checkpoint, StateDictErrorsNameTheTensors) {
  MvsNet net(MvsNetConfig{});
  c10::impl::GenericDict d(c10::StringType::get(), c10::AnyType::get());
  for (const auto& p : net->named_parameters()) d.insert(p.key(), p.value().detach().clone());
  for (const auto& b : net->named_buffers()) d.insert(b.key(), b.value().detach().clone());
  ASSERT_EQ(d.erase("feature.conv0.bn.weight"), 1u);
  d.insert_or_assign("feature.feature.bias", torch::zeros({31}));
  d.insert("extra.weight", torch::zeros({1}));
  EXPECT_THAT([&] { load_state_dict(*net, d, "weights.pt"); },
              testing::ThrowsMessage<std::runtime_error>(testing::AllOf(testing::HasSubstr("missing tensor 'feature.conv0.bn.weight'"), testing::HasSubstr("'feature.feature.bias' has shape [31]"), testing::HasSubstr("unexpected tensor 'extra.weight'"))));
}

TEST(ImageIo, PngRoundTrip) {
  const auto dir = test::temp_dir("png");
  auto img = torch::randint(0, 256, {5, 7, 3}).to(torch::kUInt8);
  write_png(dir + "/a.png", img);
  EXPECT_TRUE(torch::equal(read_image_rgb8(dir + "/a.png"), img));
  EXPECT_THROW(read_image_rgb8(dir + "/missing.png"), std::runtime_error);
}

}  // namespace
}  // namespace umvs
