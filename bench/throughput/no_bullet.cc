// Stand-in when libbullet-dev is absent: the bench prints "n/a" for Bullet.
#include "runner.h"

double RunBulletSoftBody(int64_t, double, int, int64_t* links) {
  *links = 0;
  return 0;
}
