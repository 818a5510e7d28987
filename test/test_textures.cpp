// io/texture_bank.h: photographic texture folders for synthetic scenes.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "test_util.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/texture_bank.h"

namespace umvs {
namespace {

void put_u32(std::string* s, uint32_t v) {
  for (int shift : {24, 16, 8, 0}) s->push_back(static_cast<char>((v >> shift) & 0xff));
}

// A GIMP pattern as GIMP writes it: big-endian header, name, then the pixels.
void write_pattern(const std::string& path, uint32_t width, uint32_t height, uint32_t depth, const std::string& pixels,
                   size_t cut = 0) {
  const std::string name = "test pattern";
  std::string s;
  put_u32(&s, static_cast<uint32_t>(24 + name.size() + 1));
  put_u32(&s, 1);
  put_u32(&s, width);
  put_u32(&s, height);
  put_u32(&s, depth);
  s += "GPAT";
  s += name;
  s.push_back('\0');
  s += pixels;
  std::ofstream(path, std::ios::binary) << s.substr(0, s.size() - cut);
}

std::string file_text(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(TextureBank, DecodesGimpPatterns) {
  const std::string dir = test::temp_dir("gimp_pattern");
  write_pattern(dir + "/rgb.pat", 2, 1, 3, std::string("\x0a\x14\x1e\xc8\xd2\xdc", 6));
  const torch::Tensor rgb = read_gimp_pattern(dir + "/rgb.pat");
  ASSERT_EQ(rgb.sizes(), (std::vector<int64_t>{1, 2, 3}));
  EXPECT_EQ(rgb[0][0][1].item<int>(), 20);
  EXPECT_EQ(rgb[0][1][2].item<int>(), 220);
  write_pattern(dir + "/grey_alpha.pat", 1, 2, 2, std::string("\x05\xff\x63\x00", 4));
  const torch::Tensor grey = read_gimp_pattern(dir + "/grey_alpha.pat");
  ASSERT_EQ(grey.sizes(), (std::vector<int64_t>{2, 1, 3}));
  EXPECT_EQ(grey[1][0][0].item<int>(), 99);  // grey replicated, alpha dropped
  EXPECT_EQ(grey[1][0][2].item<int>(), 99);
  write_pattern(dir + "/cut.pat", 2, 2, 3, std::string(12, 'x'), 3);
  EXPECT_THAT([&] { read_gimp_pattern(dir + "/cut.pat"); },
              testing::ThrowsMessage<std::runtime_error>(testing::AllOf(testing::HasSubstr("cut.pat"), testing::HasSubstr("truncated"))));
  std::ofstream(dir + "/not.pat") << "just some text, long enough for a header";
  EXPECT_THROW(read_gimp_pattern(dir + "/not.pat"), std::runtime_error);
  std::filesystem::remove_all(dir);
}

TEST(TextureBank, LoadsFoldersRecursivelyInOrderAndShrinks) {
  const std::string dir = test::temp_dir("texture_bank");
  std::filesystem::create_directories(dir + "/b_sub");
  write_png(dir + "/b_sub/big.png", torch::full({40, 80, 3}, 90, torch::kUInt8));
  write_pattern(dir + "/a.pat", 2, 2, 3, std::string(12, '\x40'));
  std::ofstream(dir + "/broken.jpg") << "not a jpeg";
  std::ofstream(dir + "/notes.txt") << "ignored: not an image";
  const TextureBank bank = load_texture_bank({dir}, 16);
  ASSERT_EQ(bank.images.size(), 2u);
  EXPECT_EQ(std::filesystem::path(bank.paths[0]).filename(), "a.pat");  // sorted by path
  EXPECT_EQ(bank.images[1].sizes(), (std::vector<int64_t>{8, 16, 3}));  // longest side 80 -> 16
  EXPECT_EQ(bank.images[1][3][5][1].item<int>(), 90);
  ASSERT_EQ(bank.skipped.size(), 1u);
  EXPECT_NE(bank.skipped[0].find("broken.jpg"), std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST(TextureBank, MissingOrEmptyFolderGivesAClearError) {
  const std::string dir = test::temp_dir("texture_bank_errors");
  auto message = [](const std::vector<std::string>& folders) {
    try {
      load_texture_bank(folders);
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string missing = message({dir + "/no_such_folder"});
  EXPECT_NE(missing.find(dir + "/no_such_folder"), std::string::npos) << missing;
  EXPECT_NE(missing.find("does not exist"), std::string::npos) << missing;
  std::ofstream(dir + "/readme.txt") << "no images here";
  const std::string empty = message({dir});
  EXPECT_NE(empty.find("holds no image"), std::string::npos) << empty;
  EXPECT_THROW(load_texture_bank({}), std::invalid_argument);

  // The command line says the same and writes nothing.
  const std::string out = dir + "/scene";
  const std::string cmd = test::umvs_binary() + " synth --scene corridor --views 2 --width 32 --height 24 --gt-samples 0" +
                          " --textures " + dir + "/no_such_folder --out " + out + " > " + dir + "/log.txt 2>&1";
  EXPECT_NE(std::system(cmd.c_str()), 0);
  const std::string log = file_text(dir + "/log.txt");
  EXPECT_NE(log.find("texture folder '" + dir + "/no_such_folder' does not exist"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(out));
  std::filesystem::remove_all(dir);
}

TEST(TextureBank, SynthCommandUsesTheGivenTextures) {
  const std::string dir = test::temp_dir("synth_textures_cli");
  std::filesystem::create_directories(dir + "/tex");
  write_png(dir + "/tex/red.png", torch::tensor({255, 0, 0}, torch::kUInt8).repeat({16, 16, 1}));
  const std::string cmd = test::umvs_binary() + " synth --scene corridor --views 2 --width 48 --height 32 --gt-samples 0" +
                          " --lighting-change 0 --photo-fraction 1 --textures " + dir + "/tex --out " + dir +
                          "/scene > " + dir + "/log.txt 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << file_text(dir + "/log.txt");
  EXPECT_NE(file_text(dir + "/log.txt").find("photographic textures: 1 images"), std::string::npos);
  const std::string settings = file_text(dir + "/scene/scene.txt");
  EXPECT_NE(settings.find("photo_textures 1\n"), std::string::npos) << settings;
  EXPECT_NE(settings.find("texture_folders " + dir + "/tex\n"), std::string::npos) << settings;
  // Red photographs: where they show, green and blue are 0.
  const torch::Tensor img = read_image_rgb8(dir + "/scene/images/00000000.png");
  const double red = ((img.select(2, 1) == 0) & (img.select(2, 0) > 0)).to(torch::kFloat64).mean().item<double>();
  EXPECT_GT(red, 0.2);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace umvs
