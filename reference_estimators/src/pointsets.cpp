#include "pointsets.h"

namespace re {

SobolDirections &sobol_directions() {
    static SobolDirections d;
    return d;
}

}  // namespace re
