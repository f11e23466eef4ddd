# The library graph's rules, checked on CMake's own view of it (a ctest, label unit):
#   - docs/design.md's table of the project's targets and their direct project links is the
#     graph CMake has, edge for edge;
#   - the worker, client and farm libraries link no SQLite, however indirectly: only the
#     coordinator keeps a job store;
#   - the engine links neither gRPC nor protobuf (docs/design.md: the engine knows no RPC);
#   - the scene library links no Embree and no TBB: reading scenes and writing images never
#     needs the renderer;
#   - the farm model links no protobuf, gRPC, Embree or TBB;
#   - the client links no Embree or TBB: it reads scenes and writes images, it never renders;
#   - the coordinator library links no gRPC or protobuf (the service is its only gRPC part),
#     and no Embree or TBB (it never renders).
# The layer link checks (tests/CMakeLists.txt, layer_*) hold the same rules at the symbol level.
# Configures the source tree into WORK_DIR with `cmake --graphviz`, then walks each library's
# link closure in the graph CMake writes (every edge counts: a static library's private links
# reach whatever links it).
#
#   cmake -DSOURCE_DIR=... -DWORK_DIR=... -DGENERATOR=Ninja -P tests/library_graph.cmake
cmake_minimum_required(VERSION 3.22)

foreach(var SOURCE_DIR WORK_DIR GENERATOR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "library_graph.cmake: -D${var}=... is required")
  endif()
endforeach()

set(dot ${WORK_DIR}/rayfarm.dot)
file(REMOVE ${dot})
execute_process(
  COMMAND ${CMAKE_COMMAND} -S ${SOURCE_DIR} -B ${WORK_DIR} -G ${GENERATOR} --graphviz=${dot}
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
if(NOT rc EQUAL 0 OR NOT EXISTS ${dot})
  message(FATAL_ERROR "configuring ${SOURCE_DIR} with --graphviz failed:\n${out}")
endif()

# Nodes ("node3" [ label = "rayfarm_worker" ...) and edges ("node3" -> "node7").
file(STRINGS ${dot} lines)
set(nodes "")
foreach(line IN LISTS lines)
  if(line MATCHES "^ *\"(node[0-9]+)\" \\[ label = \"([^\"]*)\"")
    set(label_${CMAKE_MATCH_1} "${CMAKE_MATCH_2}")
    set(node_of_${CMAKE_MATCH_2} ${CMAKE_MATCH_1})
    list(APPEND nodes ${CMAKE_MATCH_1})
  elseif(line MATCHES "^ *\"(node[0-9]+)\" -> \"(node[0-9]+)\"")
    list(APPEND edges_${CMAKE_MATCH_1} ${CMAKE_MATCH_2})
  endif()
endforeach()

# Fails naming the path from `target` to the first library whose lower-case name matches
# `pattern`.
function(forbid target pattern why)
  set(start ${node_of_${target}})
  if(NOT start)
    message(FATAL_ERROR "${target} is not in the build's graph (renamed? update ${CMAKE_CURRENT_LIST_FILE})")
  endif()
  set(queue ${start})
  set(seen ${start})
  set(path_${start} ${target})
  while(queue)
    list(POP_FRONT queue node)
    string(TOLOWER "${label_${node}}" name)
    if(name MATCHES "${pattern}")
      list(JOIN path_${node} " -> " chain)
      message(SEND_ERROR "${target} links ${label_${node}} (${chain}): ${why}")
      return()
    endif()
    foreach(next IN LISTS edges_${node})
      if(NOT next IN_LIST seen)
        list(APPEND seen ${next})
        list(APPEND queue ${next})
        set(path_${next} ${path_${node}} ${label_${next}})
      endif()
    endforeach()
  endwhile()
  list(LENGTH seen count)
  message(STATUS "${target}: ${count} libraries in its link closure, none matching '${pattern}'")
endfunction()

# docs/design.md's table of the project's targets and the project libraries each links directly
# must be CMake's graph, edge for edge (test and tool targets aside).
include(${CMAKE_CURRENT_LIST_DIR}/design_table.cmake)
design_table(${SOURCE_DIR} library-graph rows)
set(documented "")
foreach(row IN LISTS rows)
  if(row MATCHES "^\\| (rayfarm[a-z_]*) \\|([^|]*)\\|")
    set(target ${CMAKE_MATCH_1})
    string(REGEX MATCHALL "rayfarm[a-z_]*" links "${CMAKE_MATCH_2}")
    list(SORT links)
    list(APPEND documented ${target})
    set(doc_links_${target} "${links}")
  endif()
endforeach()
set(actual "")
foreach(node IN LISTS nodes)
  set(name ${label_${node}})
  if(name MATCHES "^rayfarm(_[a-z_]+)?$" AND NOT name STREQUAL "rayfarm_testlib")
    list(APPEND actual ${name})
    set(links "")
    foreach(next IN LISTS edges_${node})
      if(label_${next} MATCHES "^rayfarm_[a-z_]+$")
        list(APPEND links ${label_${next}})
      endif()
    endforeach()
    list(REMOVE_DUPLICATES links)
    list(SORT links)
    if(NOT DEFINED doc_links_${name})
      message(SEND_ERROR "${name} is in the build but not in docs/design.md's library table")
    elseif(NOT "${links}" STREQUAL "${doc_links_${name}}")
      message(SEND_ERROR "${name} links [${links}] but docs/design.md says [${doc_links_${name}}]")
    endif()
  endif()
endforeach()
foreach(target IN LISTS documented)
  if(NOT target IN_LIST actual)
    message(SEND_ERROR "docs/design.md lists ${target}, which the build does not have")
  endif()
endforeach()
list(LENGTH actual n)
message(STATUS "docs/design.md's library table matches CMake's graph (${n} targets)")

set(no_store "only the coordinator library keeps the SQLite job store")
forbid(rayfarm_worker "sqlite" "${no_store}")
forbid(rayfarm_client "sqlite" "${no_store}")
forbid(rayfarm_farm "sqlite" "${no_store}")
forbid(rayfarm_wire "sqlite" "${no_store}")
forbid(rayfarm_engine "grpc|protobuf" "the engine knows no RPC")
forbid(rayfarm_scene "embree|tbb|grpc|protobuf"
       "the scene library reads scenes and writes images without the renderer or RPC")
forbid(rayfarm_farm "protobuf|grpc|embree|tbb" "the farm model is plain types")
forbid(rayfarm_client "embree|tbb" "the client never renders")
forbid(rayfarm_coordinator "grpc|protobuf|embree|tbb"
       "the coordinator library knows no RPC (service.cpp is its gRPC adapter) and never renders")
