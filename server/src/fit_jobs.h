// Fitting a recorded session's model in the server (issue 34): POST /api/sessions/{id}/fit (admin)
// queues a job that replays the session's recording through the model it ran (or one named) and
// stores the fitted model as that model's next version, the fit's report in its metadata; GET
// /api/sessions/{id}/fit says where the job is (queued, running with its progress, done with the
// new version, failed with the reason). One fit runs at a time, on a thread of its own at the
// lowest CPU priority, so that sessions and requests keep their cores.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "server_internal.h"

namespace idms::server {

class FitJobs;

// The fit routes; the returned jobs are the server's to stop (Stop, then Join once the I/O
// threads are done).
std::shared_ptr<FitJobs> AppendFitRoutes(ServerCore& core, std::vector<Route>* routes);

// A running fit ends at its next solver iteration ("stopped"); queued ones do not start.
void StopFits(FitJobs& jobs);
void JoinFits(FitJobs& jobs);
// idms_fit_jobs{state} and idms_fits_total{result}, for /metrics.
std::string FitMetrics(FitJobs& jobs);

}  // namespace idms::server
