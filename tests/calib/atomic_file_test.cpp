#include "calib/atomic_file.h"

#include <gtest/gtest.h>

#include <stdexcept>

#include "calib/error.h"
#include "tests/calib/io_temp_dir.h"

namespace omni {
namespace {

using omni::testing::ReadBytes;
using omni::testing::TempDir;

TEST(AtomicFile, WritesAndReplacesLeavingNoTmp) {
  TempDir dir;
  const auto path = dir / "out.txt";
  WriteTextFileAtomically(path, "first\n");
  EXPECT_EQ(ReadBytes(path), "first\n");
  WriteFileAtomically(path, [](std::ostream& stream) { stream << "second"; });
  EXPECT_EQ(ReadBytes(path), "second");
  EXPECT_FALSE(std::filesystem::exists(dir / "out.txt.tmp"));
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path()),
                          std::filesystem::directory_iterator()),
            1);
}

TEST(AtomicFile, BinaryContentIsKeptByteForByte) {
  TempDir dir;
  const std::string bytes("a\r\n\0b\n\xff", 7);
  WriteFileAtomically(
      dir / "b.bin", [&](std::ostream& stream) { stream.write(bytes.data(), bytes.size()); }, true);
  EXPECT_EQ(ReadBytes(dir / "b.bin"), bytes);
}

TEST(AtomicFile, MissingFolderIsAnErrorAndCreatesNothing) {
  TempDir dir;
  const auto path = dir / "no_such_folder" / "out.txt";
  try {
    WriteTextFileAtomically(path, "text");
    FAIL() << "no error";
  } catch (const InputError& error) {
    const std::string message = error.what();
    EXPECT_EQ(message.rfind(path.string() + ": cannot write: ", 0), 0u) << message;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "no_such_folder"));
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

TEST(AtomicFile, FailingWriterKeepsTheOldFileAndRemovesTmp) {
  TempDir dir;
  const auto path = dir / "keep.txt";
  WriteTextFileAtomically(path, "old");
  EXPECT_THROW(WriteFileAtomically(path,
                                   [](std::ostream& stream) {
                                     stream << "half";
                                     throw std::runtime_error("writer failed");
                                   }),
               std::runtime_error);
  EXPECT_EQ(ReadBytes(path), "old");
  EXPECT_FALSE(std::filesystem::exists(dir / "keep.txt.tmp"));
}

}  // namespace
}  // namespace omni
