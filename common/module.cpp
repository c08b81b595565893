#include "common/module.h"

#include <dlfcn.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <system_error>
#include <vector>

#include "common/error.h"

namespace reshutter {

void* loadModule(const char* envVar, const std::string& fileName, const std::string& builtPath, const char* entry, const std::string& what) {
  std::vector<std::string> candidates;
  const char* env = std::getenv(envVar);
  if (env && *env) {
    candidates.push_back(env);  // the user's choice: nothing else
  } else {
    std::error_code ec;
    const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (!ec) candidates.push_back((self.parent_path() / fileName).string());
    if (!builtPath.empty() && std::find(candidates.begin(), candidates.end(), builtPath) == candidates.end()) candidates.push_back(builtPath);
  }
  std::string tried;
  for (const std::string& path : candidates) {
    std::string why;
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) {
      why = path + ": no such file";
    } else if (void* module = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL); !module) {
      // RTLD_LOCAL: the module's libraries keep their symbols to themselves.
      const char* e = ::dlerror();
      why = e ? e : path + ": cannot be loaded";
    } else if (void* symbol = ::dlsym(module, entry)) {
      return symbol;
    } else {
      why = cat(path, ": not reshutter's ", what, " module (no ", entry, "; one from another build?)");
    }
    tried += (tried.empty() ? "" : "; ") + why;
  }
  fail(candidates.empty() ? fileName : candidates.front(), "cannot load the ", what, " module (", tried, ")",
       env && *env ? "" : cat("; ", envVar, " names another path"));
}

}  // namespace reshutter
