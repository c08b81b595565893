// libFuzzer target for the farm's job description reader (farm/job.h, job.txt): the input is
// written as a job directory's job.txt and read back; a job that reads must map every task index
// to frames and a tile inside its window, and must write and read back as itself. Only
// reshutter::Error may escape; anything else is a finding.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

#include "common/error.h"
#include "farm/job.h"

using namespace reshutter;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string dir = [] {
    std::string d = std::filesystem::temp_directory_path().string() + "/fuzz_farm_job." + std::to_string(getpid());
    std::filesystem::create_directories(d);
    return d;
  }();
  if (FILE* f = std::fopen((dir + "/job.txt").c_str(), "wb")) {
    std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  try {
    const farm::Job job = farm::Job::load(dir);
    const size_t tasks = job.tasks();
    for (size_t i : {size_t(0), tasks / 2, tasks - 1}) {
      if (i >= tasks || tasks > 100000) break;
      const farm::Job::Task t = job.task(i);
      if (t.frames.empty() || t.crop.x0 < job.window.x0 || t.crop.x1 > job.window.x1 || t.crop.y0 < job.window.y0 || t.crop.y1 > job.window.y1 ||
          t.crop.x0 >= t.crop.x1 || t.crop.y0 >= t.crop.y1)
        __builtin_trap();
    }
    if (job.frames.size() < 100000) {
      job.save();
      if (!(farm::Job::load(dir) == job)) __builtin_trap();
    }
  } catch (const Error&) {
  }
  return 0;
}
