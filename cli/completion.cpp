// `rayfarm completion bash`: a bash completion script made from the command line's own
// definition (every subcommand and its flags), so it never goes stale.
#include <cstdio>
#include <string>

#include "cli/commands.h"

namespace rf::cli {

namespace {

// The flags a command takes, space-separated (--long and -s forms).
std::string flags_of(const CLI::App& app) {
  std::string out;
  for (const CLI::Option* o : app.get_options()) {
    for (const std::string& l : o->get_lnames()) out += " --" + l;
    for (const std::string& s : o->get_snames()) out += " -" + s;
  }
  return out;
}

std::string bash_script(const CLI::App& app) {
  std::string commands, cases;
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; })) {
    const std::string name = sub->get_name();
    commands += " " + name;
    std::string nested;
    for (const CLI::App* n : sub->get_subcommands([](const CLI::App*) { return true; }))
      nested += " " + n->get_name();
    cases += "    " + name + ") words='" + nested + flags_of(*sub) + "' ;;\n";
  }
  return "# bash completion for rayfarm: source <(rayfarm completion bash)\n"
         "_rayfarm() {\n"
         "  local cur=${COMP_WORDS[COMP_CWORD]} cmd='' words i\n"
         "  for ((i = 1; i < COMP_CWORD; i++)); do\n"
         "    case ${COMP_WORDS[i]} in -*) ;; *) cmd=${COMP_WORDS[i]}; break ;; esac\n"
         "  done\n"
         "  case $cmd in\n"
         "    '') words='" +
         commands + flags_of(app) + "' ;;\n" + cases +
         "    *) words='' ;;\n"
         "  esac\n"
         "  if [[ $cur == -* || -z $cmd ]]; then\n"
         "    COMPREPLY=($(compgen -W \"$words\" -- \"$cur\"))\n"
         "  else\n"
         "    COMPREPLY=($(compgen -f -- \"$cur\"))  # scenes, outputs, job ids typed\n"
         "  fi\n"
         "}\n"
         "complete -o filenames -F _rayfarm rayfarm ./rayfarm\n";
}

}  // namespace

void add_completion_command(CLI::App& app, std::vector<Command>& out) {
  auto shell = std::make_shared<std::string>("bash");
  auto* c = app.add_subcommand("completion", "print a shell completion script (bash)");
  c->add_option("shell", *shell, "the shell (bash)")->check(CLI::IsMember({"bash"}));
  // The lambda holds `shell`: CLI11 writes the parsed value into it after this returns.
  out.push_back({c, [&app, shell] {
                   std::fputs(bash_script(app).c_str(), stdout);
                   return 0;
                 }});
}

}  // namespace rf::cli
