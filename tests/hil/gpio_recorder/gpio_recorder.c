// SPDX-License-Identifier: GPL-2.0
/*
 * gpio_recorder: a GPIO chip with no hardware behind it that records every
 * output level the kernel drives on its lines, with the CLOCK_MONOTONIC time
 * of the call (ktime_get_ns()), so a hardware-in-the-loop test can check the
 * edges a program produced through the real GPIO character device
 * (tests/hil/qemu_run.sh). Debian's 6.1 kernel has neither gpio-sim nor
 * gpio-mockup, hence this module. Written against the gpio_chip driver API
 * of include/linux/gpio/driver.h (Linux 6.1).
 *
 * /sys/kernel/debug/gpio_recorder/events: one line "<t_ns> <line> <value>"
 * per driven level, oldest first; writing anything to it clears the log.
 */
#include <linux/debugfs.h>
#include <linux/gpio/driver.h>
#include <linux/ktime.h>
#include <linux/module.h>
#include <linux/seq_file.h>
#include <linux/spinlock.h>

static unsigned int nlines = 8;
module_param(nlines, uint, 0444);
MODULE_PARM_DESC(nlines, "number of GPIO lines (1..32)");

#define MAX_EVENTS 8192
struct level_event { u64 t_ns; u32 line; u32 value; };
static struct level_event events[MAX_EVENTS];
static unsigned int n_events;
static unsigned long n_dropped;   /* events beyond MAX_EVENTS: never silent */
static unsigned long levels;      /* bit per line: last level driven */
static unsigned long input_lines; /* bit per line: 1 = configured as input */
static DEFINE_SPINLOCK(lock);
static struct dentry *debug_dir;

static void record(unsigned int line, int value)
{
	u64 t_ns = ktime_get_ns();
	unsigned long flags;

	spin_lock_irqsave(&lock, flags);
	if (value)
		__set_bit(line, &levels);
	else
		__clear_bit(line, &levels);
	if (n_events < MAX_EVENTS)
		events[n_events++] = (struct level_event){ t_ns, line, !!value };
	else
		n_dropped++;
	spin_unlock_irqrestore(&lock, flags);
}

static void rec_set(struct gpio_chip *gc, unsigned int line, int value) { record(line, value); }
static int rec_get(struct gpio_chip *gc, unsigned int line) { return test_bit(line, &levels); }
static int rec_get_direction(struct gpio_chip *gc, unsigned int line)
{
	return test_bit(line, &input_lines) ? GPIO_LINE_DIRECTION_IN : GPIO_LINE_DIRECTION_OUT;
}
static int rec_direction_input(struct gpio_chip *gc, unsigned int line)
{
	set_bit(line, &input_lines);
	return 0;
}
static int rec_direction_output(struct gpio_chip *gc, unsigned int line, int value)
{
	clear_bit(line, &input_lines);
	record(line, value); /* requesting a line as output drives its first level */
	return 0;
}

static struct gpio_chip chip = {
	.label = "gpio-recorder", .owner = THIS_MODULE, .base = -1,
	.get_direction = rec_get_direction, .direction_input = rec_direction_input,
	.direction_output = rec_direction_output, .get = rec_get, .set = rec_set,
};

static int events_show(struct seq_file *s, void *unused)
{
	unsigned long flags;
	unsigned int i;

	spin_lock_irqsave(&lock, flags);
	seq_printf(s, "# t_ns line value (chip %s, dropped %lu)\n", chip.label, n_dropped);
	for (i = 0; i < n_events; i++)
		seq_printf(s, "%llu %u %u\n", events[i].t_ns, events[i].line, events[i].value);
	spin_unlock_irqrestore(&lock, flags);
	return 0;
}
static int events_open(struct inode *inode, struct file *file) { return single_open(file, events_show, NULL); }
static ssize_t events_clear(struct file *file, const char __user *buf, size_t len, loff_t *pos)
{
	unsigned long flags;

	spin_lock_irqsave(&lock, flags);
	n_events = 0;
	n_dropped = 0;
	spin_unlock_irqrestore(&lock, flags);
	return len;
}
static const struct file_operations events_fops = {
	.owner = THIS_MODULE, .open = events_open, .read = seq_read,
	.write = events_clear, .llseek = seq_lseek, .release = single_release,
};

static int __init gpio_recorder_init(void)
{
	int ret;

	if (nlines < 1 || nlines > 32)
		return -EINVAL;
	chip.ngpio = (u16)nlines;
	ret = gpiochip_add_data(&chip, NULL);
	if (ret)
		return ret;
	debug_dir = debugfs_create_dir("gpio_recorder", NULL);
	debugfs_create_file("events", 0600, debug_dir, NULL, &events_fops);
	return 0;
}

static void __exit gpio_recorder_exit(void)
{
	debugfs_remove_recursive(debug_dir);
	gpiochip_remove(&chip);
}

module_init(gpio_recorder_init);
module_exit(gpio_recorder_exit);
MODULE_DESCRIPTION("GPIO chip that records driven levels with timestamps (test fixture)");
MODULE_LICENSE("GPL");
