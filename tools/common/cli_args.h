// Minimal "--name value" / "--flag" command-line parsing shared by the render-core tools.
#pragma once

#include <map>
#include <set>
#include <stdexcept>
#include <string>

namespace catgs::tools {

class Args {
 public:
  // Parses argv; every option must be in `known` ("--name" takes a value, "--name!" is a flag).
  // Throws std::invalid_argument for an unknown option or a missing value.
  Args(int argc, char** argv, const std::set<std::string>& known) {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (known.count(a + "!")) {
        values_[a] = "1";
      } else if (known.count(a)) {
        if (i + 1 >= argc) throw std::invalid_argument("option " + a + " needs a value");
        values_[a] = argv[++i];
      } else {
        throw std::invalid_argument("unknown option '" + a + "'");
      }
    }
  }
  bool has(const std::string& name) const { return values_.count(name) > 0; }
  std::string get(const std::string& name, const std::string& fallback = "") const {
    auto it = values_.find(name);
    return it == values_.end() ? fallback : it->second;
  }
  // Throws std::invalid_argument when absent.
  std::string require(const std::string& name) const {
    if (!has(name)) throw std::invalid_argument("missing required option " + name);
    return get(name);
  }
  int get_int(const std::string& name, int fallback) const { return has(name) ? std::stoi(get(name)) : fallback; }
  double get_double(const std::string& name, double fallback) const {
    return has(name) ? std::stod(get(name)) : fallback;
  }

 private:
  std::map<std::string, std::string> values_;
};

}  // namespace catgs::tools
