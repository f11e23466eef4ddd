# docs/design.md's tables that tests hold the code to (library_graph.cmake, engine_layers.cmake):
# design_table(SOURCE_DIR NAME OUT) sets OUT to the lines between <!-- NAME:begin --> and
# <!-- NAME:end -->, one list element per line; a missing table fails the test.
function(design_table source_dir name out)
  file(READ ${source_dir}/docs/design.md design)
  string(REGEX MATCH "<!-- ${name}:begin -->(.*)<!-- ${name}:end -->" _ "${design}")
  if(NOT CMAKE_MATCH_1)
    message(FATAL_ERROR "docs/design.md has no ${name} table")
  endif()
  string(REPLACE "\n" ";" rows "${CMAKE_MATCH_1}")
  set(${out} "${rows}" PARENT_SCOPE)
endfunction()
