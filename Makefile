# swarmdsl's make targets (Python's own tools do the rest: see README.md).
#
#   make kilombo-local [KILOMBO_PREFIX=DIR]
#       Kilombo, the C Kilobot simulator (MIT), built headless from its sources in
#       third_party/kilombo into DIR (default build/kilombo): DIR/include/kilombo.h and
#       DIR/lib/libheadless.a, what an exported program's `make kilombo KILOMBO=DIR`
#       links. Needs a C compiler, ar and the jansson headers (Debian: libjansson-dev);
#       not CMake or SDL.

KILOMBO_PREFIX ?= build/kilombo
KILOMBO_SRC := third_party/kilombo
KILOMBO_UNITS := skilobot kbapi params stateio runsim neighbors distribution
KILOMBO_HEADERS := kilolib.h message.h message_crc.h params.h skilobot.h
KILOMBO_CFLAGS := -std=c99 -fcommon -O2 -DSKILO_HEADLESS -w
KILOMBO_OBJS := $(KILOMBO_UNITS:%=$(KILOMBO_PREFIX)/obj/%.o)

kilombo-local: $(KILOMBO_PREFIX)/lib/libheadless.a \
		$(KILOMBO_PREFIX)/include/kilombo.h \
		$(KILOMBO_HEADERS:%=$(KILOMBO_PREFIX)/include/kilombo/%)

$(KILOMBO_PREFIX)/obj/%.o: $(KILOMBO_SRC)/%.c
	@mkdir -p $(@D)
	$(CC) $(KILOMBO_CFLAGS) -c $< -o $@

$(KILOMBO_PREFIX)/lib/libheadless.a: $(KILOMBO_OBJS)
	@mkdir -p $(@D)
	rm -f $@
	ar rcs $@ $^

$(KILOMBO_PREFIX)/include/kilombo.h: $(KILOMBO_SRC)/kilombo.h
	@mkdir -p $(@D)
	cp $< $@

$(KILOMBO_PREFIX)/include/kilombo/%.h: $(KILOMBO_SRC)/%.h
	@mkdir -p $(@D)
	cp $< $@

.PHONY: kilombo-local
