// help_markdown.h — the command reference as Markdown pages, one per plugin module,
// generated from the registry alone (name, arguments, help, inputs, typed options), so
// the pages in docs/commands/ say what the installed plugins say and nothing else.
#pragma once

#include <map>
#include <string>
#include <vector>

#include <bokeh/plugin.h>

namespace bokehtool {

/// One generated page: its file name ("blur.md") and its text.
struct MarkdownPage {
    std::string file;
    std::string text;
};

/// The first line of every generated page; `bokehtool --help-markdown DIR` replaces only
/// the files that start with it.
extern const char* const kGeneratedMarker;

/// A page per module that registered commands, in load order (`host` names the host's own
/// commands; `global` marks those that apply to the whole command line), then an index
/// page (README.md) listing them.
std::vector<MarkdownPage> command_reference_pages(const bokeh::Registry& registry,
                                                  const std::string& host,
                                                  const std::map<std::string, bool>& global);

/// Write `pages` into `dir` (made if missing) and remove the generated pages there that
/// `pages` no longer has. False + `err` naming the file on failure.
bool write_markdown_pages(const std::vector<MarkdownPage>& pages, const std::string& dir,
                          std::string& err);

}  // namespace bokehtool
