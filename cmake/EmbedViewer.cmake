# Writes OUTPUT: a C++ source defining ptmkit::texture::web_viewer_files() with the contents
# of FILES (paths separated by |) as raw string literals. Run with cmake -P at build time, so an
# edit to a viewer file rebuilds the library.
string(REPLACE "|" ";" FILES "${FILES}")
set(body "")
foreach(f IN LISTS FILES)
  get_filename_component(name "${f}" NAME)
  file(READ "${f}" text)
  string(FIND "${text}" ")ptmkit_viewer\"" clash)
  if(NOT clash EQUAL -1)
    message(FATAL_ERROR "${f} contains the raw-string delimiter")
  endif()
  string(APPEND body "      {\"${name}\", R\"ptmkit_viewer(${text})ptmkit_viewer\"},\n")
endforeach()
file(WRITE "${OUTPUT}.new"
"// Generated from web/viewer by cmake/EmbedViewer.cmake: do not edit.
#include \"ptmkit/texture/web_export.h\"

namespace ptmkit::texture {

const std::vector<WebViewerFile>& web_viewer_files() {
  static const std::vector<WebViewerFile> files = {
${body}  };
  return files;
}

}  // namespace ptmkit::texture
")
file(COPY_FILE "${OUTPUT}.new" "${OUTPUT}" ONLY_IF_DIFFERENT)
file(REMOVE "${OUTPUT}.new")
