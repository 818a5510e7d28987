#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "unsup_mvs/io/child_process.h"

namespace umvs {
namespace {

std::vector<std::string> run_to_end(ChildProcess& p) {
  std::vector<std::string> lines;
  while (p.poll([&](const std::string& l) { lines.push_back(l); })) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  return lines;
}

TEST(ChildProcess, CapturesLinesAndExitCode) {
  ChildProcess p;
  p.start({"/bin/sh", "-c", "echo one; printf 'a\\rb\\n' ; echo two >&2; exit 3"});
  const auto lines = run_to_end(p);
  EXPECT_EQ(lines, (std::vector<std::string>{"one", "a", "b", "two"}));
  EXPECT_EQ(p.exit_status(), 3);
  EXPECT_FALSE(p.running());
}

TEST(ChildProcess, ArgumentsAreNotInterpretedByAShell) {
  ChildProcess p;
  p.start({"/bin/echo", "$HOME; rm -rf /", "`id`"});
  const auto lines = run_to_end(p);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0], "$HOME; rm -rf / `id`");
}

TEST(ChildProcess, StopKillsALongRunningChild) {
  ChildProcess p;
  p.start({"/bin/sleep", "30"});
  EXPECT_TRUE(p.running());
  const auto t0 = std::chrono::steady_clock::now();
  p.stop(2.0);
  EXPECT_FALSE(p.running());
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 3.0);
  EXPECT_EQ(p.exit_status(), -15);  // SIGTERM
}

TEST(ChildProcess, RefusesRelativeOrMissingPrograms) {
  ChildProcess p;
  EXPECT_THROW(p.start({"sleep", "1"}), std::runtime_error);
  EXPECT_THROW(p.start({"/nonexistent/umvs"}), std::runtime_error);
}

}  // namespace
}  // namespace umvs
