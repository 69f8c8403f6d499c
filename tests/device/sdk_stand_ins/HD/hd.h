/* A stand-in for OpenHaptics' HD/hd.h: only the declarations
 * examples/devices/openhaptics_bridge.c uses, as the HD API publishes them,
 * so that the test build compiles the bridge against palpate/device.h where
 * the SDK is absent (it is never linked or run). Not the SDK. */
#ifndef PALPATE_STAND_IN_HD_H
#define PALPATE_STAND_IN_HD_H
typedef unsigned int HHD;
typedef double HDdouble;
typedef int HDint;
typedef unsigned int HDenum;
typedef unsigned int HDErrorCode;
typedef unsigned long HDSchedulerHandle;
typedef unsigned int HDCallbackCode;
typedef unsigned short HDushort;
typedef struct {
  HDErrorCode errorCode;
  int internalErrorCode;
  HHD hHD;
} HDErrorInfo;
#define HDCALLBACK
#define HD_DEFAULT_DEVICE ((const char*)0)
#define HD_CURRENT_TRANSFORM 0x2052
#define HD_CURRENT_BUTTONS 0x2000
#define HD_CURRENT_FORCE 0x2700
#define HD_FORCE_OUTPUT 0x4000
#define HD_DEVICE_BUTTON_1 (1 << 0)
#define HD_CALLBACK_DONE 0
#define HD_CALLBACK_CONTINUE 1
#define HD_MAX_SCHEDULER_PRIORITY 0xffff
#define HD_DEFAULT_SCHEDULER_PRIORITY 0x8000
#define HD_DEVICE_ERROR(e) ((e).errorCode != 0)
typedef HDCallbackCode (*HDSchedulerCallback)(void*);
HHD hdInitDevice(const char* name);
void hdDisableDevice(HHD device);
void hdBeginFrame(HHD device);
void hdEndFrame(HHD device);
void hdGetDoublev(HDenum name, HDdouble* value);
void hdGetIntegerv(HDenum name, HDint* value);
void hdSetDoublev(HDenum name, const HDdouble* value);
void hdEnable(HDenum cap);
HDErrorInfo hdGetError(void);
const char* hdGetErrorString(HDErrorCode code);
HDSchedulerHandle hdScheduleAsynchronous(HDSchedulerCallback callback, void* data,
                                         HDushort priority);
void hdScheduleSynchronous(HDSchedulerCallback callback, void* data, HDushort priority);
void hdStartScheduler(void);
void hdStopScheduler(void);
void hdUnschedule(HDSchedulerHandle handle);
#endif
