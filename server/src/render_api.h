// Screenshots and thumbnails rendered in the server (render_api.cc): the routes, added at the
// front of the table (the thumbnail's path would otherwise match /api/models/{name}/{file}).
#pragma once

#include <vector>

#include "server_internal.h"

namespace idms::server {

// GET /api/sessions/{id}/screenshot.png and GET /api/models/{name}/thumbnail.png, served by one
// render thread (one OSMesa context) that the routes own.
void AppendRenderRoutes(ServerCore& core, std::vector<Route>* routes);

}  // namespace idms::server
