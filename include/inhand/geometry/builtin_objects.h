#pragma once
// The paper's test objects, generated in code at real size, closed, in metres. Each object's frame
// has its origin at the bounding-box centre and z along the object's tall/up axis.
#include <string>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

// Names accepted after "builtin:": cracker_box, coffee_can, juice_bottle, pill_bottle, mug.
std::vector<std::string> builtinObjectNames();

// "builtin:NAME" gives a generated object; anything else is a mesh file path (see importMesh).
// Throws Error naming the object or file when it cannot be loaded.
TriangleMesh loadObject(const std::string& spec);

bool isBuiltinSpec(const std::string& spec);

}  // namespace inhand
