/*
 * A libmodbus RTU master (C) that sends a fixed list of requests in turn, as fast as the line
 * answers: the peer of bench/master_cpu.py. Built by that bench with the system's cc and
 * libmodbus-dev (Debian), never by the package.
 *
 * Usage: libmodbus_master PORT BAUD PARITY STOP GAP_US HEX_REQUEST...
 * Each HEX_REQUEST is one request without its CRC (unit, function, data), as the node sent
 * it; libmodbus adds the CRC (modbus_send_raw_request) and reads the reply by its function
 * code (modbus_receive_confirmation), as its modbus_read_registers does. It prints "ready",
 * sends the requests in turn until SIGTERM, then prints "answered N failed F". The bench
 * reads its CPU from the scheduler and its transactions from the wire.
 *
 * libmodbus keeps no silence before a request: on a real line a UART's latency gives one,
 * on a pty the next request would follow the reply at once and the paced wire would lose it
 * (a gap violation). So after each transaction the helper sleeps GAP_US (the 3.5-character
 * gap, one clock_nanosleep), as the node keeps the gap itself.
 */
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <modbus.h>

#define MAX_REQUESTS 64

static volatile sig_atomic_t stopped = 0;

static void stop(int signal_number)
{
  (void)signal_number;
  stopped = 1;
}

static int parse_hex(const char *text, uint8_t *out, int size)
{
  int length = (int)strlen(text) / 2;
  if (length < 2 || length > size || strlen(text) % 2) {
    return -1;
  }
  for (int index = 0; index < length; index++) {
    unsigned int byte;
    if (sscanf(text + 2 * index, "%2x", &byte) != 1) {
      return -1;
    }
    out[index] = (uint8_t)byte;
  }
  return length;
}

int main(int argc, char **argv)
{
  if (argc < 7) {
    fprintf(stderr, "usage: %s PORT BAUD PARITY STOP GAP_US HEX_REQUEST...\n", argv[0]);
    return 2;
  }
  uint8_t requests[MAX_REQUESTS][MODBUS_RTU_MAX_ADU_LENGTH];
  int lengths[MAX_REQUESTS];
  int count = argc - 6;
  if (count > MAX_REQUESTS) {
    fprintf(stderr, "at most %d requests\n", MAX_REQUESTS);
    return 2;
  }
  for (int index = 0; index < count; index++) {
    lengths[index] = parse_hex(argv[6 + index], requests[index], MODBUS_RTU_MAX_ADU_LENGTH - 2);
    if (lengths[index] < 0) {
      fprintf(stderr, "not a request in hex: %s\n", argv[6 + index]);
      return 2;
    }
  }
  struct sigaction action;
  memset(&action, 0, sizeof(action));
  action.sa_handler = stop;  /* libmodbus retries a select cut by it: ends within 0.5 s */
  sigaction(SIGTERM, &action, NULL);
  modbus_t *context = modbus_new_rtu(argv[1], atoi(argv[2]), argv[3][0], 8, atoi(argv[4]));
  if (context == NULL || modbus_connect(context) == -1) {
    fprintf(stderr, "cannot open %s: %s\n", argv[1], modbus_strerror(errno));
    return 1;
  }
  modbus_set_response_timeout(context, 0, 500000);
  printf("ready\n");
  fflush(stdout);
  long gap_us = atol(argv[5]);
  struct timespec gap = {gap_us / 1000000, (gap_us % 1000000) * 1000};
  long answered = 0, failed = 0;
  uint8_t reply[MODBUS_RTU_MAX_ADU_LENGTH];
  for (int index = 0; !stopped; index = (index + 1) % count) {
    modbus_set_slave(context, requests[index][0]);
    if (modbus_send_raw_request(context, requests[index], lengths[index]) == -1 ||
        modbus_receive_confirmation(context, reply) == -1) {
      if (!stopped) {
        failed++;
        modbus_flush(context);
      }
    } else {
      answered++;
    }
    clock_nanosleep(CLOCK_MONOTONIC, 0, &gap, NULL);
  }
  printf("answered %ld failed %ld\n", answered, failed);
  modbus_close(context);
  modbus_free(context);
  return 0;
}
