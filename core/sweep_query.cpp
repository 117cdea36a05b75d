// Placeholder: implemented by the core issue.
#include "core/sweep_query.h"
