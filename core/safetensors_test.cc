#include "core/safetensors.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

namespace headforge {
namespace {

SafeTensorsFile Sample() {
  SafeTensorsFile file;
  file.metadata["format"] = "pt";
  const float a[6] = {1, -2, 3.5f, 4, 5, 6e-8f};
  file.tensors.push_back(SafeTensor::Float32("net.layer0.weight", {2, 3}, a));
  const float b[1] = {42};
  file.tensors.push_back(SafeTensor::Float32("net.bias", {}, b));
  SafeTensor ints;
  ints.name = "binding";
  ints.dtype = "I64";
  ints.shape = {3};
  const int64_t values[3] = {0, -1, int64_t(1) << 40};
  ints.bytes.assign(reinterpret_cast<const uint8_t*>(values), reinterpret_cast<const uint8_t*>(values) + 24);
  file.tensors.push_back(ints);
  return file;
}

TEST(Safetensors, RoundTripKeepsNamesShapesDtypesBytesAndOrder) {
  const fs::path path = fs::temp_directory_path() / "hf_safetensors_round.safetensors";
  const SafeTensorsFile written = Sample();
  ASSERT_TRUE(WriteSafetensors(path, written).ok());
  SafeTensorsFile read;
  const Status s = ReadSafetensors(path, &read);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(read.metadata, written.metadata);
  ASSERT_EQ(read.tensors.size(), written.tensors.size());
  for (size_t i = 0; i < read.tensors.size(); ++i) {
    EXPECT_EQ(read.tensors[i].name, written.tensors[i].name);
    EXPECT_EQ(read.tensors[i].dtype, written.tensors[i].dtype);
    EXPECT_EQ(read.tensors[i].shape, written.tensors[i].shape);
    EXPECT_EQ(read.tensors[i].bytes, written.tensors[i].bytes);
  }
  EXPECT_EQ(read.Find("net.bias")->ToFloats(), std::vector<float>{42});
  // The data section starts 8-byte aligned.
  std::ifstream in(path, std::ios::binary);
  uint64_t length = 0;
  in.read(reinterpret_cast<char*>(&length), 8);
  EXPECT_EQ(length % 8, 0u);
  fs::remove(path);
}

TEST(Safetensors, RejectsWhatItCannotWriteFaithfully) {
  const fs::path path = fs::temp_directory_path() / "hf_safetensors_bad.safetensors";
  SafeTensorsFile file = Sample();
  file.tensors[1].name = file.tensors[0].name;
  EXPECT_FALSE(WriteSafetensors(path, file).ok());
  file = Sample();
  file.tensors[0].bytes.pop_back();
  EXPECT_FALSE(WriteSafetensors(path, file).ok());
  file = Sample();
  file.tensors[0].dtype = "F8";
  EXPECT_FALSE(WriteSafetensors(path, file).ok());
  EXPECT_FALSE(fs::exists(path));
}

TEST(Safetensors, DamagedFilesGiveDataErrors) {
  const fs::path path = fs::temp_directory_path() / "hf_safetensors_damaged.safetensors";
  ASSERT_TRUE(WriteSafetensors(path, Sample()).ok());
  std::string good;
  ASSERT_TRUE(ReadFileToString(path, &good).ok());
  const auto expect_error = [&](const std::string& contents, const char* what) {
    ASSERT_TRUE(WriteFileAtomic(path, contents).ok());
    SafeTensorsFile read;
    const Status s = ReadSafetensors(path, &read);
    EXPECT_FALSE(s.ok()) << what;
    EXPECT_EQ(s.code(), Status::Code::kDataError) << what;
  };
  expect_error(good.substr(0, 5), "shorter than the length field");
  expect_error(good.substr(0, good.size() - 4), "tensor bytes cut off");
  expect_error(good.substr(0, 40), "header cut off");
  std::string garbled = good;
  garbled[9] = '#';
  expect_error(garbled, "header not JSON");
  std::string huge = good;
  huge[7] = char(0x7f);
  expect_error(huge, "absurd header length");
  fs::remove(path);
}

#ifdef HEADFORGE_PYTHON3
// A second reader, written from the format's description with Python's json
// and struct only, reads what the writer wrote.
TEST(Safetensors, IndependentPythonReaderAgrees) {
  const fs::path dir = fs::temp_directory_path() / "hf_safetensors_python";
  fs::create_directories(dir);
  ASSERT_TRUE(WriteSafetensors(dir / "w.safetensors", Sample()).ok());
  const std::string script =
      "import json, struct, sys\n"
      "raw = open(sys.argv[1], 'rb').read()\n"
      "n = struct.unpack('<Q', raw[:8])[0]\n"
      "head = json.loads(raw[8:8 + n])\n"
      "data = raw[8 + n:]\n"
      "meta = head.pop('__metadata__', {})\n"
      "fmt = {'F32': 'f', 'I64': 'q'}\n"
      "out = [meta.get('format', '')]\n"
      "for name in sorted(head):\n"
      "    e = head[name]\n"
      "    b, end = e['data_offsets']\n"
      "    count = 1\n"
      "    for d in e['shape']: count *= d\n"
      "    vals = struct.unpack('<%d%s' % (count, fmt[e['dtype']]), data[b:end])\n"
      "    out.append('%s %s %s %s' % (name, e['dtype'], 'x'.join(map(str, e['shape'])), ' '.join(str(v) if isinstance(v, int) else '%.9g' % v for v in vals)))\n"
      "print('\\n'.join(out))\n";
  ASSERT_TRUE(WriteFileAtomic(dir / "read.py", script).ok());
  const std::string command = std::string(HEADFORGE_PYTHON3) + " " + (dir / "read.py").string() + " " +
                              (dir / "w.safetensors").string() + " > " + (dir / "out.txt").string();
  ASSERT_EQ(std::system(command.c_str()), 0);
  std::string printed;
  ASSERT_TRUE(ReadFileToString(dir / "out.txt", &printed).ok());
  EXPECT_EQ(printed,
            "pt\n"
            "binding I64 3 0 -1 1099511627776\n"
            "net.bias F32  42\n"
            "net.layer0.weight F32 2x3 1 -2 3.5 4 5 5.99999979e-08\n");
  fs::remove_all(dir);
}
#endif

}  // namespace
}  // namespace headforge
