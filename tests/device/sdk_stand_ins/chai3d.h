// A stand-in for CHAI3D's chai3d.h: only what
// examples/devices/chai3d_bridge.cpp uses, with CHAI3D 3.2's signatures, so
// that the test build compiles the bridge against palpate/device.h where
// CHAI3D is absent (it is never linked or run). Not CHAI3D.
#pragma once
#include <memory>
namespace chai3d {
struct cVector3d {
  cVector3d() = default;
  cVector3d(double x, double y, double z) : v{x, y, z} {}
  double operator()(int i) const { return v[i]; }
  double v[3] = {0, 0, 0};
};
struct cMatrix3d {
  double operator()(int i, int j) const { return m[i][j]; }
  double m[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
};
class cGenericHapticDevice {
 public:
  virtual ~cGenericHapticDevice() = default;
  virtual bool open();
  virtual bool close();
  virtual bool calibrate(bool a_forceCalibration = false);
  virtual bool getPosition(cVector3d& a_position);
  virtual bool getRotation(cMatrix3d& a_rotation);
  virtual bool getGripperAngleRad(double& a_angle);
  virtual bool setForceAndTorqueAndGripperForce(const cVector3d& a_force, const cVector3d& a_torque,
                                                const double a_gripperForce);
};
using cGenericHapticDevicePtr = std::shared_ptr<cGenericHapticDevice>;
class cHapticDeviceHandler {
 public:
  bool getDevice(cGenericHapticDevicePtr& a_hapticDevice, unsigned int a_index = 0);
};
enum CThreadPriority { CTHREAD_PRIORITY_GRAPHICS, CTHREAD_PRIORITY_HAPTICS };
class cThread {
 public:
  void start(void (*a_function)(void*), const CThreadPriority a_level, void* a_arg);
};
void cSleepMs(const unsigned int a_interval);
}  // namespace chai3d
