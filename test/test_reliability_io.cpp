// Fault injection for file writes and child processes (docs/reliability.md, "ROS nodes and file
// writes"): links planted where a write goes, paths that leave their folder, FIFOs and devices
// where a model file should be, leftovers of interrupted writes, a parent killed under its child.
#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "test_util.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/child_process.h"
#include "unsup_mvs/io/file_safety.h"
#include "unsup_mvs/io/input_limits.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}
using test::write_text;
void write_hello(const std::string& path) {
  write_file_atomically(path, [](std::ostream& out) { out << "hello"; });
}

std::vector<std::string> temp_files_in(const std::string& dir) {
  std::vector<std::string> found;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().filename().string().find(kTempInfix) != std::string::npos) found.push_back(e.path().string());
  }
  return found;
}

TEST(AtomicWrite, NeverWritesThroughALinkPlantedAtTheOldTemporaryName) {
  const auto dir = test::temp_dir("atomic_planted_tmp");
  fs::create_directories(dir + "/out");
  write_text(dir + "/victim.txt", "precious");
  // The name the writer used to pick ("<path>.tmp-<pid>") and a few neighbours.
  for (int pid : {::getpid(), ::getpid() + 1}) {
    fs::create_symlink(dir + "/victim.txt", dir + "/out/x.ply.tmp-" + std::to_string(pid));
  }
  write_hello(dir + "/out/x.ply");
  EXPECT_EQ(read_text(dir + "/victim.txt"), "precious");
  EXPECT_EQ(read_text(dir + "/out/x.ply"), "hello");
  EXPECT_FALSE(fs::is_symlink(dir + "/out/x.ply"));
}

TEST(AtomicWrite, RefusesALinkOrFolderAtTheFinalName) {
  const auto dir = test::temp_dir("atomic_planted_final");
  write_text(dir + "/victim.txt", "precious");
  fs::create_symlink(dir + "/victim.txt", dir + "/x.ply");
  EXPECT_THAT([&] { write_hello(dir + "/x.ply"); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("is a symbolic link; refusing to replace it")));
  EXPECT_TRUE(fs::is_symlink(dir + "/x.ply"));
  EXPECT_EQ(read_text(dir + "/victim.txt"), "precious");
  fs::create_directories(dir + "/folder.ply");
  EXPECT_THROW(write_hello(dir + "/folder.ply"), std::runtime_error);
  EXPECT_TRUE(temp_files_in(dir).empty());
}

TEST(AtomicWrite, AFailedWriteKeepsTheOldFileAndLeavesNoTemporaryFile) {
  const auto dir = test::temp_dir("atomic_fail");
  write_hello(dir + "/x.txt");
  EXPECT_THROW(write_file_atomically(dir + "/x.txt", [](std::ostream& out) {
                 out << "half";
                 throw std::runtime_error("disk on fire");
               }),
               std::runtime_error);
  EXPECT_EQ(read_text(dir + "/x.txt"), "hello");
  EXPECT_TRUE(temp_files_in(dir).empty());
  // The new file gets the usual permissions (mkstemp alone would make it owner-only).
  const mode_t mask = ::umask(022);
  ::umask(mask);
  EXPECT_EQ(fs::status(dir + "/x.txt").permissions(), static_cast<fs::perms>(0666 & ~mask));
}

TEST(CopyFileToNewName, NeverReplacesAFileOrALink) {
  const auto dir = test::temp_dir("copy_new");
  write_text(dir + "/new.pt", "new model");
  write_text(dir + "/served.pt", "served model");
  fs::create_symlink(dir + "/served.pt", dir + "/link.pt");
  fs::create_symlink(dir + "/nowhere.pt", dir + "/dangling.pt");
  for (const char* taken : {"/served.pt", "/link.pt", "/dangling.pt"}) {
    EXPECT_THAT([&] { copy_file_to_new_name(dir + "/new.pt", dir + taken); },
                testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("already exists; refusing to replace it")))
        << taken;
  }
  EXPECT_EQ(read_text(dir + "/served.pt"), "served model");
  EXPECT_FALSE(fs::exists(dir + "/nowhere.pt"));
  copy_file_to_new_name(dir + "/new.pt", dir + "/fresh.pt");
  EXPECT_EQ(read_text(dir + "/fresh.pt"), "new model");
  EXPECT_TRUE(temp_files_in(dir).empty());
}

TEST(PathInside, DotDotAndLinksCannotLeaveTheFolder) {
  const auto dir = test::temp_dir("inside");
  fs::create_directories(dir + "/save");
  fs::create_directories(dir + "/outside");
  fs::create_symlink(dir + "/outside", dir + "/save/escape");
  EXPECT_EQ(resolve_inside(dir + "/save", "a/b.ply"), dir + "/save/a/b.ply");
  EXPECT_EQ(resolve_inside(dir + "/save", dir + "/save/c.ply"), dir + "/save/c.ply");
  for (const std::string& bad : {std::string("out/../../outside/x.ply"), std::string("escape/x.ply"),
                                 dir + "/outside/x.ply", std::string("/etc/passwd"), std::string("."),
                                 std::string("")}) {
    EXPECT_THAT([&] { resolve_inside(dir + "/save", bad); },
                testing::ThrowsMessage<std::invalid_argument>(
                    testing::HasSubstr(bad.empty() ? "empty path" : "outside the allowed folder")))
        << "'" << bad << "'";
  }
}

TEST(CheckedFileSize, RefusesFifosDevicesFoldersAndHugeFilesWithoutBlocking) {
  const auto dir = test::temp_dir("regular");
  ASSERT_EQ(::mkfifo((dir + "/fifo.pt").c_str(), 0600), 0);
  write_text(dir + "/small.pt", "12345");
  {
    std::ofstream big(dir + "/big.pt");
  }
  fs::resize_file(dir + "/big.pt", 3u << 20);  // sparse: 3 MiB claimed, nothing written
  EXPECT_EQ(checked_file_size(dir + "/small.pt", 5, "checkpoint"), 5u);
  auto refused = [&](const std::string& path, uint64_t limit, const std::string& why) {
    EXPECT_THAT([&] { checked_file_size(path, limit, "checkpoint"); },
                testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr(why)))
        << path;
  };
  const auto t0 = std::chrono::steady_clock::now();
  refused(dir + "/fifo.pt", 1 << 30, "is a FIFO, not a regular file");  // no writer: a blocking open would hang
  refused("/dev/zero", 1 << 30, "is a device, not a regular file");
  refused(dir, 1 << 30, "is a folder, not a regular file");
  refused(dir + "/big.pt", 2u << 20, "is 3145728 bytes, more than the limit of 2097152");
  refused(dir + "/missing.pt", 1 << 30, "cannot open");
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 2.0);
}

TEST(RemoveStaleTempFiles, RemovesLeftoversAndLinksButNothingElse) {
  const auto dir = test::temp_dir("stale");
  fs::create_directories(dir + "/models/ft-1");
  fs::create_directories(dir + "/elsewhere");
  write_text(dir + "/elsewhere/keep.pt", "keep");
  write_text(dir + "/models/ft-1/best.pt", "model");
  write_text(dir + "/models/ft-1/best.pt.tmp-12345", "half a model");
  write_text(dir + "/models/a.pt.tmp-Xy12Ab", "half");
  fs::create_symlink(dir + "/elsewhere/keep.pt", dir + "/models/b.pt.tmp-999");
  fs::create_symlink(dir + "/elsewhere", dir + "/models/linked_folder");
  write_text(dir + "/elsewhere/c.pt.tmp-1", "not ours");
  EXPECT_EQ(remove_stale_temp_files(dir + "/models"), 3);
  EXPECT_EQ(read_text(dir + "/models/ft-1/best.pt"), "model");
  EXPECT_EQ(read_text(dir + "/elsewhere/keep.pt"), "keep");
  EXPECT_TRUE(fs::exists(dir + "/elsewhere/c.pt.tmp-1")) << "followed a link out of the folder";
  EXPECT_FALSE(fs::exists(fs::symlink_status(dir + "/models/b.pt.tmp-999")));
  EXPECT_EQ(remove_stale_temp_files(dir + "/models"), 0);
}

bool process_gone(pid_t pid) {
  // Gone, or a zombie waiting for a reaper that is not us.
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return true;
  const auto close = line.rfind(')');
  return close != std::string::npos && close + 2 < line.size() && line[close + 2] == 'Z';
}

TEST(ChildProcess, DiesWhenItsParentIsKilled) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t parent = ::fork();
  ASSERT_GE(parent, 0);
  if (parent == 0) {  // a stand-in for the trainer node: starts a long child, then is SIGKILLed
    ::close(fds[0]);
    ChildProcess child;
    child.start({"/bin/sleep", "60"});
    const pid_t pid = child.pid();
    (void)!::write(fds[1], &pid, sizeof(pid));
    ::pause();
    ::_exit(0);
  }
  ::close(fds[1]);
  pid_t child = -1;
  ASSERT_EQ(::read(fds[0], &child, sizeof(child)), static_cast<ssize_t>(sizeof(child)));
  ::close(fds[0]);
  ASSERT_FALSE(process_gone(child));
  ::kill(parent, SIGKILL);
  ::waitpid(parent, nullptr, 0);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!process_gone(child) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  const bool gone = process_gone(child);
  if (!gone) ::kill(child, SIGKILL);
  EXPECT_TRUE(gone) << "the child outlived its killed parent";
}

}  // namespace
}  // namespace umvs
