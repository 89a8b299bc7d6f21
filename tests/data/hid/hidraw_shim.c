/* LD_PRELOAD shim for running hidapi's hidraw backend against a umockdev-emulated
 * /dev/hidraw node (tests only).
 *
 * umockdev emulates the node as a stream and does not answer the hidraw ioctls, so:
 *  - HIDIOCGRDESCSIZE / HIDIOCGRDESC return the report descriptor given (hex) in the
 *    environment variable MOP_HID_DESCRIPTOR; every other ioctl goes to the next library
 *    (umockdev's preload, then libc).
 *  - Report boundaries: umockdev delivers script data as a byte stream, so reports written
 *    close together would merge into one read. With MOP_HID_FRAMED=1 each report in the script
 *    is preceded by its length (one byte) and read() on a hidraw node returns exactly one
 *    report, as the kernel's hidraw does.
 *  - Unplugging: while the file named by MOP_HID_UNPLUG exists, a hidraw node behaves as a
 *    removed device does: poll() reports POLLHUP|POLLERR, read() fails with ENODEV and open()
 *    fails with ENOENT. Removing the file "plugs it back in".
 *  - Feature reports: HIDIOCGFEATURE for report id NN returns the bytes (hex, report id
 *    first) in MOP_HID_FEATURE_NN (NN two lower-case hex digits), or fails with EPIPE, as a
 *    device that has no such report does. With MOP_HID_FEATURE_FAIL_FIRST=1 the first request
 *    fails anyway (a receiver asked before its controller is there).
 * Built by the test fixture: gcc -shared -fPIC -o hidraw_shim.so hidraw_shim.c -ldl
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <linux/hidraw.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <unistd.h>

#define MAX_FD 4096
static unsigned char is_hidraw[MAX_FD];

static int unplugged(void) {
    const char *flag = getenv("MOP_HID_UNPLUG");
    struct stat st;
    return flag && *flag && stat(flag, &st) == 0;
}

static int hidraw_path(const char *path) {
    return path && strstr(path, "/dev/hidraw") != NULL;
}

static int hex_bytes(const char *hex, unsigned char *out, int max) {
    int n = 0;
    while (hex[0] && hex[1] && n < max) {
        unsigned value;
        if (sscanf(hex, "%2x", &value) != 1) return -1;
        out[n++] = (unsigned char)value;
        hex += 2;
    }
    return n;
}

static int descriptor(unsigned char *out, int max) {
    const char *hex = getenv("MOP_HID_DESCRIPTOR");
    return hex ? hex_bytes(hex, out, max) : -1;
}

static int feature(unsigned char *buffer, size_t size) {
    static int requests = 0;
    const char *fail_first = getenv("MOP_HID_FEATURE_FAIL_FIRST");
    if (requests++ == 0 && fail_first && strcmp(fail_first, "1") == 0) {
        errno = EPIPE;
        return -1;
    }
    char name[32];
    snprintf(name, sizeof name, "MOP_HID_FEATURE_%02x", buffer[0]);
    const char *hex = getenv(name);
    unsigned char bytes[4096];
    int n = hex ? hex_bytes(hex, bytes, sizeof bytes) : -1;
    if (n <= 0) { errno = EPIPE; return -1; }
    if ((size_t)n > size) n = (int)size;
    memcpy(buffer, bytes, n);
    return n;
}

static int opened(int fd, const char *path) {
    if (fd >= 0 && fd < MAX_FD) is_hidraw[fd] = hidraw_path(path);
    return fd;
}

int open(const char *path, int flags, ...) {
    static int (*next)(const char *, int, ...);
    mode_t mode = 0;
    if (flags & (O_CREAT | O_TMPFILE)) { va_list ap; va_start(ap, flags); mode = va_arg(ap, mode_t); va_end(ap); }
    if (!next) next = dlsym(RTLD_NEXT, "open");
    if (hidraw_path(path) && unplugged()) { errno = ENOENT; return -1; }
    return opened(next(path, flags, mode), path);
}

int open64(const char *path, int flags, ...) {
    static int (*next)(const char *, int, ...);
    mode_t mode = 0;
    if (flags & (O_CREAT | O_TMPFILE)) { va_list ap; va_start(ap, flags); mode = va_arg(ap, mode_t); va_end(ap); }
    if (!next) next = dlsym(RTLD_NEXT, "open64");
    if (hidraw_path(path) && unplugged()) { errno = ENOENT; return -1; }
    return opened(next(path, flags, mode), path);
}

int close(int fd) {
    static int (*next)(int);
    if (!next) next = dlsym(RTLD_NEXT, "close");
    if (fd >= 0 && fd < MAX_FD) is_hidraw[fd] = 0;
    return next(fd);
}

static ssize_t read_fully(ssize_t (*next)(int, void *, size_t), int fd, unsigned char *out,
                          size_t size) {
    size_t done = 0;
    while (done < size) {
        ssize_t got = next(fd, out + done, size - done);
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) return got;
        done += (size_t)got;
    }
    return (ssize_t)done;
}

ssize_t read(int fd, void *buffer, size_t count) {
    static ssize_t (*next)(int, void *, size_t);
    if (!next) next = dlsym(RTLD_NEXT, "read");
    if (fd < 0 || fd >= MAX_FD || !is_hidraw[fd]) return next(fd, buffer, count);
    if (unplugged()) { errno = ENODEV; return -1; }
    const char *framed = getenv("MOP_HID_FRAMED");
    if (!framed || strcmp(framed, "1") != 0) return next(fd, buffer, count);
    unsigned char length, report[256];
    ssize_t got = read_fully(next, fd, &length, 1);
    if (got <= 0) return got;
    got = read_fully(next, fd, report, length);
    if (got < 0) return got;
    /* like hidraw: a report longer than the buffer is cut to the buffer */
    size_t size = (size_t)got < count ? (size_t)got : count;
    memcpy(buffer, report, size);
    return (ssize_t)size;
}

int poll(struct pollfd *fds, nfds_t count, int timeout) {
    static int (*next)(struct pollfd *, nfds_t, int);
    if (!next) next = dlsym(RTLD_NEXT, "poll");
    if (unplugged()) {
        int hits = 0;
        for (nfds_t i = 0; i < count; i++) {
            if (fds[i].fd >= 0 && fds[i].fd < MAX_FD && is_hidraw[fds[i].fd]) {
                fds[i].revents = POLLHUP | POLLERR;
                hits++;
            }
        }
        if (hits) return hits;
    }
    return next(fds, count, timeout);
}

int ioctl(int fd, unsigned long request, ...) {
    static int (*next)(int, unsigned long, ...);
    va_list ap;
    va_start(ap, request);
    void *arg = va_arg(ap, void *);
    va_end(ap);
    if (!next) next = dlsym(RTLD_NEXT, "ioctl");
    if (_IOC_TYPE(request) == 'H' && _IOC_NR(request) == 0x07 && fd >= 0 && fd < MAX_FD
            && is_hidraw[fd]) {                          /* HIDIOCGFEATURE(len) */
        return feature(arg, _IOC_SIZE(request));
    }
    if (request == HIDIOCGRDESCSIZE || request == HIDIOCGRDESC) {
        unsigned char bytes[HID_MAX_DESCRIPTOR_SIZE];
        int size = descriptor(bytes, sizeof bytes);
        if (size >= 0) {
            if (request == HIDIOCGRDESCSIZE) {
                *(int *)arg = size;
            } else {
                struct hidraw_report_descriptor *out = arg;
                memcpy(out->value, bytes, size);
                out->size = size;
            }
            return 0;
        }
    }
    return next(fd, request, arg);
}
