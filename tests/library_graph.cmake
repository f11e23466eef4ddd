# The library graph's rules, checked on CMake's own view of it (a ctest, label unit):
#   - the worker, client and farm libraries link no SQLite, however indirectly: only the
#     coordinator keeps a job store;
#   - the engine links neither gRPC nor protobuf (DESIGN.md: the engine never includes gRPC).
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

set(no_store "only the coordinator library keeps the SQLite job store")
forbid(rayfarm_worker "sqlite" "${no_store}")
forbid(rayfarm_client "sqlite" "${no_store}")
forbid(rayfarm_farm "sqlite" "${no_store}")
forbid(rayfarm_engine "grpc|protobuf" "the engine knows no RPC")
