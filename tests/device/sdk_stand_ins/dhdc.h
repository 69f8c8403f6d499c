// A stand-in for the Force Dimension SDK's dhdc.h: only the declarations
// examples/devices/force_dimension_bridge.cpp uses, as the DHD API
// publishes them (a device id is a char, -1 by default), so that the test
// build compiles the bridge against palpate/device.h where the SDK is
// absent (it is never linked or run). Not the SDK.
#pragma once
using uchar = unsigned char;
#define DHD_ON 1
int dhdOpen();
int dhdClose(char ID = -1);
const char* dhdErrorGetLastStr();
int dhdEnableForce(uchar val, char ID = -1);
bool dhdHasWrist(char ID = -1);
bool dhdHasGripper(char ID = -1);
int dhdGetPosition(double* px, double* py, double* pz, char ID = -1);
int dhdGetOrientationFrame(double matrix[3][3], char ID = -1);
int dhdGetGripperAngleRad(double* a, char ID = -1);
int dhdSetForceAndTorqueAndGripperForce(double fx, double fy, double fz, double tx, double ty,
                                        double tz, double fg, char ID = -1);
