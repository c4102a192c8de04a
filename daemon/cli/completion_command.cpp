// `imuemu completion`: a bash completion script made from the command line
// itself (CLI11's tree of subcommands and options), so it cannot lag behind
// a new command or option. The Debian package installs it as
// /usr/share/bash-completion/completions/imuemu (debian/rules);
// tests/cli/test_completion.cpp drives it in bash against --help.
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "daemon/cli/commands.hpp"

namespace imuemu::cli {
namespace {

std::vector<const CLI::App*> subcommands_of(const CLI::App& app) {
  std::vector<const CLI::App*> out;
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; })) out.push_back(sub);
  return out;
}

// One entry per command path ("imuemu", "imuemu fault inject": bash refuses
// an empty key): its subcommands and its options.
void describe(const CLI::App& app, const std::string& path, std::ostringstream& subs, std::ostringstream& opts) {
  std::string sub_words;
  for (const CLI::App* sub : subcommands_of(app)) sub_words += (sub_words.empty() ? "" : " ") + sub->get_name();
  std::string opt_words;
  for (const CLI::Option* o : app.get_options()) {
    for (const std::string& l : o->get_lnames()) opt_words += (opt_words.empty() ? "--" : " --") + l;
    for (const std::string& s : o->get_snames()) opt_words += (opt_words.empty() ? "-" : " -") + s;
  }
  subs << "  [\"" << path << "\"]=\"" << sub_words << "\"\n";
  opts << "  [\"" << path << "\"]=\"" << opt_words << "\"\n";
  for (const CLI::App* sub : subcommands_of(app))
    describe(*sub, path + " " + sub->get_name(), subs, opts);
}

}  // namespace

std::string bash_completion_script(const CLI::App& app) {
  std::ostringstream subs;
  std::ostringstream opts;
  describe(app, "imuemu", subs, opts);
  std::ostringstream out;
  out << "# bash completion for imuemu, made by `imuemu completion` from its own command line.\n"
         "declare -gA _imuemu_subcommands=(\n"
      << subs.str()
      << ")\n"
         "declare -gA _imuemu_options=(\n"
      << opts.str()
      << ")\n"
         "_imuemu() {\n"
         "  local cur=${COMP_WORDS[COMP_CWORD]} path=imuemu word i\n"
         "  # The command path so far: each word that names a subcommand of the path before it.\n"
         "  for ((i = 1; i < COMP_CWORD; i++)); do\n"
         "    word=${COMP_WORDS[i]}\n"
         "    if [[ \" ${_imuemu_subcommands[$path]} \" == *\" $word \"* ]]; then path=\"$path $word\"; fi\n"
         "  done\n"
         "  if [[ $cur == -* ]]; then\n"
         "    mapfile -t COMPREPLY < <(compgen -W \"${_imuemu_options[$path]}\" -- \"$cur\")\n"
         "  elif [[ -n ${_imuemu_subcommands[$path]} ]]; then\n"
         "    mapfile -t COMPREPLY < <(compgen -W \"${_imuemu_subcommands[$path]}\" -- \"$cur\")\n"
         "  else\n"
         "    mapfile -t COMPREPLY < <(compgen -f -- \"$cur\")\n"
         "  fi\n"
         "}\n"
         "complete -o filenames -F _imuemu imuemu\n";
  return out.str();
}

}  // namespace imuemu::cli
