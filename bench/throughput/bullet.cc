// Bullet's btSoftBody stepped on the same atom/element network as the idms throughput bench.
#include <BulletSoftBody/btDefaultSoftBodySolver.h>
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>
#include <btBulletDynamicsCommon.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "idms/sim/generate.h"
#include "runner.h"

double RunBulletSoftBody(int64_t atoms, double seconds, int reps, int64_t* links) {
  const int32_t side = static_cast<int32_t>(std::lround(std::sqrt(atoms / 3.0)));
  const idms::Model model = idms::GenerateSlab(idms::SlabOptions{.rows = side, .cols = side, .decimals = -1});

  // A world with the soft body alone: no rigid bodies, no gravity, no collisions to speak of.
  btSoftBodyRigidBodyCollisionConfiguration config;
  btCollisionDispatcher dispatcher(&config);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDefaultSoftBodySolver soft_solver;
  btSoftRigidDynamicsWorld world(&dispatcher, &broadphase, &solver, &config, &soft_solver);
  world.setGravity(btVector3(0, 0, 0));
  btSoftBodyWorldInfo& info = world.getWorldInfo();
  info.m_gravity.setValue(0, 0, 0);
  info.m_sparsesdf.Initialize();

  std::vector<btVector3> x(model.num_atoms);
  std::vector<btScalar> m(model.num_atoms);
  for (int32_t i = 0; i < model.num_atoms; ++i) {
    x[i].setValue(model.atom_pos_eq[3 * i], model.atom_pos_eq[3 * i + 1],
                  model.atom_pos_eq[3 * i + 2] + (model.atom_fixed[i] ? 0 : 0.01 * std::sin(0.37 * i)));
    m[i] = model.atom_fixed[i] ? 0 : model.atom_mass[i];  // mass 0 = fixed in Bullet
  }
  auto* body = new btSoftBody(&info, model.num_atoms, x.data(), m.data());
  btSoftBody::Material* material = body->appendMaterial();
  material->m_kLST = 0.5;
  for (int32_t e = 0; e < model.num_elems; ++e)
    body->appendLink(model.elem_atoms[2 * e], model.elem_atoms[2 * e + 1], material);
  body->m_cfg.piterations = 1;
  body->m_cfg.collisions = 0;
  body->m_cfg.kDP = 0.01;
  world.addSoftBody(body);
  *links = body->m_links.size();

  std::vector<double> rates;
  for (int rep = 0; rep < reps; ++rep) {
    int64_t steps = 0;
    const double start = ThreadCpuSeconds();
    double elapsed = 0;
    while (elapsed < seconds) {
      world.stepSimulation(1e-3, 0, 1e-3);
      ++steps;
      elapsed = ThreadCpuSeconds() - start;
    }
    rates.push_back(static_cast<double>(body->m_links.size()) * steps / elapsed);
  }
  world.removeSoftBody(body);
  delete body;
  std::sort(rates.begin(), rates.end());
  return rates[rates.size() / 2];
}
