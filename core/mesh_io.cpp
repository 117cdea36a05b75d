// Placeholder: implemented by the core issue.
#include "core/mesh_io.h"
