// SPDX-License-Identifier: GPL-3.0-or-later
// sphles docs man|bash-completion: the manual page and the bash completion, generated from the
// CLI11 declarations of the commands (the same ones that parse the command line), so they never
// disagree with it. The build writes both next to the program and installs them.
#include <algorithm>
#include <cstdio>
#include <set>
#include <string>
#include <vector>

#include "app/commands.hpp"
#include "scene/presets.hpp"
#include "scene/schema.hpp"
#include "sim/scene.hpp"

namespace sphles::app {

namespace {

/// The commands shown to users (the job's worker and this generator are hidden: no group).
std::vector<const CLI::App*> visible_commands(const CLI::App& app) {
  return app.get_subcommands([](const CLI::App* c) { return !c->get_group().empty(); });
}

std::vector<const CLI::Option*> options_of(const CLI::App& command, bool positional) {
  return command.get_options([positional](const CLI::Option* o) {
    return o->get_positional() == positional && o->get_name() != "--help" &&
           o->get_name() != "-h,--help";
  });
}

/// Text for roff: backslashes escaped, '-' as \-, a leading '.' or '\'' guarded.
std::string roff(const std::string& text) {
  std::string out;
  for (const char c : text) {
    if (c == '\\')
      out += "\\e";
    else if (c == '-')
      out += "\\-";
    else
      out += c;
  }
  if (!out.empty() && (out[0] == '.' || out[0] == '\'')) out = "\\&" + out;
  return out;
}

std::string option_names(const CLI::Option& o) {
  std::string names;
  for (const std::string& s : o.get_snames()) names += (names.empty() ? "-" : ", -") + s;
  for (const std::string& l : o.get_lnames()) names += (names.empty() ? "--" : ", --") + l;
  return names;
}

std::string synopsis(const CLI::App& command) {
  std::string text = "sphles " + command.get_name() + " [OPTIONS]";
  for (const CLI::Option* p : options_of(command, true)) {
    const std::string name = p->get_type_name().empty() ? p->get_name(true) : p->get_type_name();
    text += p->get_required() ? " " + name : " [" + name + "]";
  }
  return text;
}

}  // namespace

std::string man_page(const CLI::App& app) {
  std::string m;
  m += ".TH SPHLES 1 \"\" \"sphles " SPHLES_VERSION "\" \"User Commands\"\n";
  m += ".SH NAME\nsphles \\- SPH\\-LES turbulence simulations, their analysis and a service to "
       "watch them\n";
  m += ".SH SYNOPSIS\n.B sphles\n\\fICOMMAND\\fR [\\fIOPTIONS\\fR]\n.br\n.B sphles\n"
       "\\fICOMMAND\\fR \\fB\\-\\-help\\fR\n";
  m += ".SH DESCRIPTION\n" + roff(app.get_description()) + "\n";
  m += ".SH COMMANDS\n";
  for (const CLI::App* c : visible_commands(app)) {
    m += ".SS \"" + roff(synopsis(*c)) + "\"\n";
    m += roff(c->get_description()) + ".\n";
    const std::string footer = c->get_footer();
    if (!footer.empty() && footer != app.get_footer()) m += ".PP\n" + roff(footer) + "\n";
    for (const CLI::Option* p : options_of(*c, true))
      m += ".TP\n.I " + roff(p->get_type_name().empty() ? p->get_name(true) : p->get_type_name()) +
           "\n" + roff(p->get_description()) + "\n";
    for (const CLI::Option* o : options_of(*c, false)) {
      if (o->get_type_size_max() > 0 && !o->get_type_name().empty())
        m += ".TP\n.BI \"" + roff(option_names(*o)) + " \" \"" + roff(o->get_type_name()) + "\"\n";
      else
        m += ".TP\n.B " + roff(option_names(*o)) + "\n";
      m += roff(o->get_description()) + "\n";
    }
  }
  m += ".SH EXIT STATUS\n0 success; 1 runtime failure (I/O, blow\\-up, a run stopped by a "
       "signal); 2 bad command line or scene (the message names the field and the reason).\n";
  m += ".SH FILES\nScenes: scenes/*.json of the source tree; the packing cache "
       "~/.cache/sphles/packing ($XDG_CACHE_HOME/sphles/packing).\n";
  m += ".SH LICENSE\nGPL\\-3.0\\-or\\-later: GNU GPL version 3 or later "
       "<https://gnu.org/licenses/gpl.html>, the text in LICENSE of the source tree. This is free "
       "software: you are free to change and redistribute it. There is NO WARRANTY, to the extent "
       "permitted by law.\n";
  m += ".SH SEE ALSO\nREADME.md and docs/ of the sphles source tree: docs/scenes.md (every scene "
       "key), docs/api.md (the service), docs/scaling.md (MPI).\n";
  return m;
}

namespace {

/// The values an option's validator lists in its type name ("LEVEL:{trace,debug}" -> "trace
/// debug"), empty when it lists none.
std::string listed_values(const CLI::Option& option) {
  const std::string type = option.get_type_name();
  const std::size_t open = type.find('{'), close = type.find('}', open);
  if (open == std::string::npos || close == std::string::npos) return "";
  std::string values = type.substr(open + 1, close - open - 1);
  std::replace(values.begin(), values.end(), ',', ' ');
  return values;
}

}  // namespace

std::string bash_completion(const CLI::App& app, const std::vector<std::string>& presets) {
  std::string commands;
  for (const CLI::App* c : visible_commands(app))
    commands += (commands.empty() ? "" : " ") + c->get_name();
  std::string preset_words;
  for (const std::string& p : presets) preset_words += (preset_words.empty() ? "" : " ") + p;
  std::string s =
      "# bash completion for sphles (generated by 'sphles docs bash-completion' from its "
      "command line)\n"
      "_sphles() {\n"
      "  local cur=\"${COMP_WORDS[COMP_CWORD]}\" prev=\"${COMP_WORDS[COMP_CWORD-1]}\"\n"
      "  local opts=\"\" dirs=\"\" files=\"\" scenes=0\n"
      "  if [ \"$COMP_CWORD\" -eq 1 ]; then\n"
      "    COMPREPLY=( $(compgen -W \"" +
      commands +
      " --help --version\" -- \"$cur\") )\n"
      "    return\n"
      "  fi\n"
      "  case \"${COMP_WORDS[1]}\" in\n";
  // An option's listed values (--log-level's levels), and the scene's keys after --set.
  std::string value_cases;
  std::set<std::string> with_values;
  for (const CLI::App* c : visible_commands(app))
    for (const CLI::Option* o : options_of(*c, false))
      if (const std::string values = listed_values(*o); !values.empty())
        for (const std::string& l : o->get_lnames())
          if (with_values.insert(l).second)
            value_cases += "    --" + l + ") COMPREPLY=( $(compgen -W \"" + values +
                           "\" -- \"$cur\") ); return ;;\n";
  std::string keys;
  for (const std::string& field : scene::scene_schema_fields()) keys += " " + field + "=";
  for (const CLI::App* c : visible_commands(app)) {
    std::string opts = "--help", dirs, files;
    bool scenes = false;
    for (const CLI::Option* o : options_of(*c, false)) {
      for (const std::string& l : o->get_lnames()) {
        opts += " --" + l;
        const std::string type = o->get_type_name();
        if (type.find("DIR") != std::string::npos) dirs += " --" + l;
        if (type.find(".json") != std::string::npos || type.find(".h5") != std::string::npos)
          files += " --" + l;
      }
    }
    for (const CLI::Option* p : options_of(*c, true))
      if (p->get_type_name().find("PRESET") != std::string::npos) scenes = true;
    s += "    " + c->get_name() + ") opts=\"" + opts + "\" dirs=\"" + dirs + "\" files=\"" + files +
         "\" scenes=" + (scenes ? "1" : "0") + " ;;\n";
  }
  s += "    *) return ;;\n"
       "  esac\n"
       "  case \"$prev\" in\n" +
       value_cases + "    --set) compopt -o nospace 2>/dev/null; COMPREPLY=( $(compgen -W \"" +
       keys +
       "\" -- \"$cur\") ); return ;;\n"
       "  esac\n"
       "  if [[ \" $dirs \" == *\" $prev \"* ]]; then\n"
       "    COMPREPLY=( $(compgen -d -- \"$cur\") )\n"
       "  elif [[ \" $files \" == *\" $prev \"* ]]; then\n"
       "    COMPREPLY=( $(compgen -f -- \"$cur\") )\n"
       "  elif [[ \"$cur\" == -* ]]; then\n"
       "    COMPREPLY=( $(compgen -W \"$opts\" -- \"$cur\") )\n"
       "  elif [ \"$scenes\" = 1 ]; then\n"
       "    COMPREPLY=( $(compgen -W \"" +
       preset_words +
       "\" -- \"$cur\") $(compgen -f -- \"$cur\") )\n"
       "  else\n"
       "    COMPREPLY=( $(compgen -f -- \"$cur\") )\n"
       "  fi\n"
       "}\n"
       "complete -F _sphles sphles\n";
  return s;
}

void add_docs_command(CLI::App& app, int& exit_code) {
  auto what = std::make_shared<std::string>();
  CLI::App* docs = app.add_subcommand("docs", "print the manual page or the bash completion");
  docs->group("");  // for the build, not in the help
  docs->add_option("what", *what, "man or bash-completion")
      ->required()
      ->check(CLI::IsMember({"man", "bash-completion"}));
  docs->callback([&app, what, &exit_code] {
    const std::string text =
        *what == "man" ? man_page(app) : bash_completion(app, scene::preset_names());
    std::fputs(text.c_str(), stdout);
    exit_code = kExitOk;
  });
}

}  // namespace sphles::app
