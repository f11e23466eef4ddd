# The rayfarm binary's start: its 320 shared libraries (260 of them OpenImageIO's: OpenCV, GDAL and
# the libraries GDAL reads through) take ~0.2 s to load, most of it in symbol lookups. A lookup
# tries the libraries of the global scope in order (the executable's NEEDED entries, then theirs,
# breadth first), and libraries such as OpenVDB and Xerces bind most of their own symbols through
# it from deep in that order. Naming the libraries that the most bindings resolve to first on the
# link line puts them first in the scope: ~0.14 s instead of ~0.2 s for `rayfarm --help`
# (docs/performance.md). The list is bench/load_order.py's ranking on Debian 12 without the
# libraries the binary links anyway (the C and C++ runtimes, gRPC, OpenSSL, OpenImageIO,
# protobuf, SQLite), which keep their places: it holds only libraries that the named imported
# targets load through their own dependencies (found by ldd; one not found is skipped), so the
# process loads no library it did not load before, and the runtime packages that bring
# OpenImageIO bring them (deploy/check.sh reads the list the build writes, load_order.txt). Which
# copy of a vague-linkage symbol (an inline function, a template instance) a library binds to can
# change with the order, as it does with any change of dependencies; they are one definition.
set(RAYFARM_FRONT_LOADED
    libopenvdb.so.10.0 libxerces-c-3.2.so libgdal.so.32 libgeos.so.3.11.1 libproj.so.25
    libdcmdata.so.17 libpoppler.so.126 libgdcmMSFF.so.3.0 libkmldom.so.1 libopencv_core.so.406
    libnetcdf.so.19 libglib-2.0.so.0 libOpenEXR-3_1.so.30 libOpenColorIO.so.2.1
    libhdf5_serial.so.103 liblog4cplus-2.0.so.3 libspatialite.so.7 libgeos_c.so.1
    librttopo.so.1 libnss3.so libdfalt.so.0 libnettle.so.8 libmbedcrypto.so.7 libgio-2.0.so.0)

# rayfarm_load_order(TARGET IMPORTED_TARGET...): TARGET's link line starts with the libraries of
# RAYFARM_FRONT_LOADED that the imported targets' libraries load (ldd), in that order, and
# ${CMAKE_BINARY_DIR}/load_order.txt names them (empty when none). Nothing with sanitizers (their
# runtime must load first) or without ldd.
function(rayfarm_load_order target)
  file(WRITE "${CMAKE_BINARY_DIR}/load_order.txt" "")
  find_program(RAYFARM_LDD ldd)
  if(RAYFARM_SANITIZE OR NOT RAYFARM_LDD OR NOT CMAKE_SYSTEM_NAME STREQUAL "Linux")
    return()
  endif()
  set(loaded "")
  foreach(imported IN LISTS ARGN)
    get_target_property(configs ${imported} IMPORTED_CONFIGURATIONS)
    if(NOT configs)
      set(configs "")  # IMPORTED_LOCATION without a configuration suffix
    endif()
    foreach(config IN ITEMS ${configs} "")
      if(config)
        set(config "_${config}")
      endif()
      get_target_property(location ${imported} IMPORTED_LOCATION${config})
      get_target_property(soname ${imported} IMPORTED_SONAME${config})
      if(location)
        execute_process(COMMAND ${RAYFARM_LDD} ${location} OUTPUT_VARIABLE out ERROR_QUIET)
        string(APPEND loaded "${out}\n\t${soname} => ${location} \n")
      endif()
    endforeach()
  endforeach()
  set(paths "")
  foreach(name IN LISTS RAYFARM_FRONT_LOADED)
    string(REPLACE "." "\\." pattern "${name}")
    string(REPLACE "+" "\\+" pattern "${pattern}")
    if(loaded MATCHES "[\t /]${pattern} => (/[^ \n]+)")  # not "=> not found"
      list(APPEND paths "${CMAKE_MATCH_1}")
      file(APPEND "${CMAKE_BINARY_DIR}/load_order.txt" "${name}\n")
    endif()
  endforeach()
  if(paths)
    list(REMOVE_DUPLICATES paths)
    list(JOIN paths " " joined)
    target_link_options(${target} BEFORE PRIVATE
                        "SHELL:-Wl,--push-state,--no-as-needed ${joined} -Wl,--pop-state")
  endif()
endfunction()
